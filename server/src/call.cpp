#include "call.hpp"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>

#include "sglc/log/log_line.hpp"
#include "sglc/storage/map_store.hpp"
#include "sglc/types.hpp"
#include "sglc/wire/error.hpp"

namespace sglc::server {
namespace {

using storage::StorageError;

grpc::StatusCode toGrpc(StorageError::Code code) {
  switch (code) {
    case StorageError::Code::kInvalidArgument:
      return grpc::StatusCode::INVALID_ARGUMENT;
    case StorageError::Code::kNotFound:
      return grpc::StatusCode::NOT_FOUND;
    case StorageError::Code::kAlreadyExists:
      return grpc::StatusCode::ALREADY_EXISTS;
    case StorageError::Code::kFull:
      return grpc::StatusCode::RESOURCE_EXHAUSTED;
    case StorageError::Code::kBusy:
      return grpc::StatusCode::UNAVAILABLE;
    case StorageError::Code::kReadOnly:
    case StorageError::Code::kUnavailable:
      return grpc::StatusCode::UNAVAILABLE;
    case StorageError::Code::kCorrupt:
      return grpc::StatusCode::DATA_LOSS;
    default:
      return grpc::StatusCode::INTERNAL;
  }
}

// Names in messages come from clients: control characters are escaped (a NUL cut the message short, a
// newline split it) and long text is cut at a UTF-8 boundary (a 200 kB robot name echoed back exceeded the
// client's metadata limit and turned NOT_FOUND into RESOURCE_EXHAUSTED).
std::string bounded(const std::string& text, std::size_t max_bytes) {
  std::string out;
  for (const unsigned char c : text) {
    if (out.size() >= max_bytes) break;
    if (c < 0x20 || c == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
  }
  if (out.size() < text.size() && out.size() >= max_bytes) {
    out.resize(max_bytes);
    while (!out.empty() && (static_cast<unsigned char>(out.back()) & 0xC0) == 0x80) out.pop_back();
    if (!out.empty() && static_cast<unsigned char>(out.back()) >= 0xC0) out.pop_back();
    out += "... (" + std::to_string(text.size()) + " bytes)";
  }
  return out;
}

grpc::Status rawStatusOf(std::exception_ptr error, std::string* detail) {
  try {
    std::rethrow_exception(error);
  } catch (const RpcError& e) {
    return grpc::Status(e.code(), e.what());
  } catch (const StorageError& e) {
    *detail = e.detail();
    return grpc::Status(toGrpc(e.code()), e.what());
  } catch (const wire::WireError& e) {
    return grpc::Status(e.code(), e.what());
  } catch (const InputError& e) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, e.what());
  } catch (const std::bad_alloc&) {
    return grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED, "the server is out of memory");
  } catch (const std::exception& e) {
    *detail = e.what();
    return grpc::Status(grpc::StatusCode::INTERNAL, "internal error (the server's log has the details)");
  } catch (...) {
    return grpc::Status(grpc::StatusCode::INTERNAL, "internal error");
  }
}

}  // namespace

grpc::Status statusOf(std::exception_ptr error, std::string* detail) {
  const grpc::Status status = rawStatusOf(error, detail);
  return grpc::Status(status.error_code(), bounded(status.error_message(), kMaxStatusMessageBytes));
}

grpc::Status logCall(const grpc::ServerContextBase& ctx, const CallLog& log, const grpc::Status& status,
                     const std::string& detail) {
  nlohmann::ordered_json line = {{"event", "rpc"},
                                 {"method", log.method},
                                 {"map", bounded(log.map, kMaxStatusMessageBytes)},
                                 {"robot", bounded(log.robot, kMaxStatusMessageBytes)},
                                 {"code", wire::statusCodeName(status.error_code())},
                                 {"ms", std::round(msSince(log.start) * 1000.0) / 1000.0},
                                 {"peer", ctx.peer()}};
  if (log.messages >= 0) line["messages"] = log.messages;
  if (!status.ok()) line["error"] = status.error_message();
  if (!detail.empty()) line["detail"] = detail;
  if (status.ok())
    spdlog::info("{}", logging::logLine(line));
  else
    spdlog::warn("{}", logging::logLine(line));
  return status;
}

void checkAlive(const grpc::ServerContextBase* ctx) {
  // The deadline first: past it gRPC also reports the call cancelled, and the log should say which it was.
  if (std::chrono::system_clock::now() > ctx->deadline())
    throw RpcError(grpc::StatusCode::DEADLINE_EXCEEDED, "deadline exceeded during processing; nothing was stored");
  if (ctx->IsCancelled()) throw RpcError(grpc::StatusCode::CANCELLED, "the client cancelled the call");
}

}  // namespace sglc::server

namespace sglc::server {
namespace {

namespace gx = grpc::experimental;

class BadRequestInterceptor final : public gx::Interceptor {
 public:
  explicit BadRequestInterceptor(gx::ServerRpcInfo* info) : info_(info) {}
  void Intercept(gx::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(gx::InterceptionHookPoints::POST_RECV_MESSAGE) &&
        methods->GetRecvMessage() == nullptr)
      unparsed_ = true;
    if (methods->QueryInterceptionHookPoint(gx::InterceptionHookPoints::PRE_SEND_STATUS)) {
      const auto status = methods->GetSendStatus();
      // Handlers always give a message; an INTERNAL without one is gRPC's own parse failure. Other codes with no
      // message parsed (RESOURCE_EXHAUSTED when the thread pool is full) stay as they are.
      if (status.error_code() == grpc::StatusCode::INTERNAL && (unparsed_ || status.error_message().empty()))
        methods->ModifySendStatus(
            grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                         std::string("the request is not a valid protobuf message for ") + info_->method()));
    }
    methods->Proceed();
  }

 private:
  gx::ServerRpcInfo* info_;
  bool unparsed_ = false;
};

class BadRequestInterceptorFactory final : public gx::ServerInterceptorFactoryInterface {
 public:
  gx::Interceptor* CreateServerInterceptor(gx::ServerRpcInfo* info) override {
    return info->type() == gx::ServerRpcInfo::Type::UNARY ? new BadRequestInterceptor(info) : nullptr;
  }
};

}  // namespace

std::unique_ptr<gx::ServerInterceptorFactoryInterface> makeBadRequestInterceptorFactory() {
  return std::make_unique<BadRequestInterceptorFactory>();
}

}  // namespace sglc::server
