// Fuzzing protobuf parsing of every request message of sglc.v1 (every message of proto/sglc/v1/sglc.proto whose
// name ends in "Request", and IngestChunk), found through the descriptor pool so that new requests are covered
// without changing this test. ParseFromString must not crash or throw; a message it accepts must re-serialise
// and re-parse to an equal message (MessageDifferencer, NaN equal to NaN) and serialise to the same bytes again.
#include <google/protobuf/descriptor.h>
#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <google/protobuf/message.h>
#include <google/protobuf/stubs/logging.h>
#include <google/protobuf/util/field_comparator.h>
#include <google/protobuf/util/message_differencer.h>

#include "fuzz_util.hpp"
#include "sglc/v1/sglc.pb.h"

namespace sglc {
namespace {

namespace pb = google::protobuf;
using fuzz::Outcome;
using fuzz::Rng;

std::vector<const pb::Descriptor*> requestTypes() {
  const pb::FileDescriptor* file = v1::IngestRequest::descriptor()->file();
  std::vector<const pb::Descriptor*> out;
  for (int i = 0; i < file->message_type_count(); ++i) {
    const pb::Descriptor* d = file->message_type(i);
    const std::string& name = d->name();
    const bool request = name.size() >= 7 && name.compare(name.size() - 7, 7, "Request") == 0;
    if (request || name == "IngestChunk") out.push_back(d);
  }
  return out;
}

std::string randomString(Rng& rng, bool utf8) {
  static const std::vector<std::string> samples = {"",          "m",           "robot-1",   "run",
                                                   "session/2", "caf\xc3\xa9", "backup.db", std::string(300, 'x')};
  std::string s = samples[fuzz::below(rng, samples.size())];
  if (!utf8 && fuzz::chance(rng, 50)) {
    s.resize(fuzz::below(rng, 64));
    for (auto& c : s) c = static_cast<char>(rng());
  }
  return s;
}

// Fills a message with random values through reflection (every field set with probability 1/2, repeated
// fields with 0..3 elements, nested messages to depth 4). Strings stay valid UTF-8, so the result parses.
void fill(pb::Message& m, Rng& rng, int depth) {
  const pb::Descriptor* d = m.GetDescriptor();
  const pb::Reflection* r = m.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const pb::FieldDescriptor* f = d->field(i);
    if (fuzz::chance(rng, 50)) continue;
    if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE && depth >= 4) continue;
    const int count = f->is_repeated() ? static_cast<int>(fuzz::below(rng, 4)) : 1;
    for (int k = 0; k < count; ++k) {
      const bool rep = f->is_repeated();
      const std::uint64_t bits = fuzz::chance(rng, 50)
                                     ? fuzz::interestingIntegers()[fuzz::below(rng, fuzz::interestingIntegers().size())]
                                     : rng();
      const double real =
          fuzz::chance(rng, 30) ? fuzz::interestingReal(rng) : std::uniform_real_distribution<double>(-100, 100)(rng);
      switch (f->cpp_type()) {
        case pb::FieldDescriptor::CPPTYPE_INT32:
          rep ? r->AddInt32(&m, f, static_cast<std::int32_t>(bits))
              : r->SetInt32(&m, f, static_cast<std::int32_t>(bits));
          break;
        case pb::FieldDescriptor::CPPTYPE_INT64:
          rep ? r->AddInt64(&m, f, static_cast<std::int64_t>(bits))
              : r->SetInt64(&m, f, static_cast<std::int64_t>(bits));
          break;
        case pb::FieldDescriptor::CPPTYPE_UINT32:
          rep ? r->AddUInt32(&m, f, static_cast<std::uint32_t>(bits))
              : r->SetUInt32(&m, f, static_cast<std::uint32_t>(bits));
          break;
        case pb::FieldDescriptor::CPPTYPE_UINT64:
          rep ? r->AddUInt64(&m, f, bits) : r->SetUInt64(&m, f, bits);
          break;
        case pb::FieldDescriptor::CPPTYPE_DOUBLE:
          rep ? r->AddDouble(&m, f, real) : r->SetDouble(&m, f, real);
          break;
        case pb::FieldDescriptor::CPPTYPE_FLOAT:
          rep ? r->AddFloat(&m, f, static_cast<float>(real)) : r->SetFloat(&m, f, static_cast<float>(real));
          break;
        case pb::FieldDescriptor::CPPTYPE_BOOL:
          rep ? r->AddBool(&m, f, bits & 1) : r->SetBool(&m, f, bits & 1);
          break;
        case pb::FieldDescriptor::CPPTYPE_ENUM: {
          const int v =
              fuzz::chance(rng, 80)
                  ? f->enum_type()->value(static_cast<int>(fuzz::below(rng, f->enum_type()->value_count())))->number()
                  : static_cast<int>(bits);  // proto3 enums are open
          rep ? r->AddEnumValue(&m, f, v) : r->SetEnumValue(&m, f, v);
          break;
        }
        case pb::FieldDescriptor::CPPTYPE_STRING: {
          const bool utf8 = f->type() == pb::FieldDescriptor::TYPE_STRING;
          std::string s = randomString(rng, utf8);
          if (!utf8 && fuzz::chance(rng, 30)) {  // packed points / labels: whole records
            s.resize(12 * fuzz::below(rng, 20));
            for (auto& c : s) c = static_cast<char>(rng());
          }
          rep ? r->AddString(&m, f, s) : r->SetString(&m, f, s);
          break;
        }
        case pb::FieldDescriptor::CPPTYPE_MESSAGE:
          fill(rep ? *r->AddMessage(&m, f) : *r->MutableMessage(&m, f), rng, depth + 1);
          break;
      }
    }
  }
}

std::string serializeDeterministic(const pb::Message& m) {
  std::string out;
  {
    pb::io::StringOutputStream stream(&out);
    pb::io::CodedOutputStream coded(&stream);
    coded.SetSerializationDeterministic(true);
    m.SerializeToCodedStream(&coded);
  }
  return out;
}

struct ProtoCase {
  int type = 0;  // index into the request types
  std::string bytes;
};

TEST(Fuzz, RequestMessagesParse) {
  const auto types = requestTypes();
  ASSERT_GE(types.size(), 15u) << "expected every *Request of sglc.v1 and IngestChunk";
  std::string names;
  for (const auto* d : types) names += d->name() + " ";
  RecordProperty("request_types", names);
  std::vector<const pb::Message*> prototypes;
  for (const auto* d : types) {
    const pb::Message* p = pb::MessageFactory::generated_factory()->GetPrototype(d);
    ASSERT_NE(p, nullptr) << d->full_name();
    prototypes.push_back(p);
  }
  // Seed corpus: random valid messages of every type (a fixed generator), serialised.
  std::vector<std::vector<std::string>> corpus(types.size());
  std::vector<std::string> all;
  {
    Rng rng(20240601);
    for (std::size_t t = 0; t < types.size(); ++t)
      for (int k = 0; k < 6; ++k) {
        std::unique_ptr<pb::Message> m(prototypes[t]->New());
        if (k > 0) fill(*m, rng, 0);
        corpus[t].push_back(m->SerializeAsString());
        all.push_back(corpus[t].back());
      }
  }
  // Parse failures of invalid UTF-8 in string fields are logged as errors by protobuf: silence them here.
  pb::LogHandler* previous = pb::SetLogHandler(nullptr);
  const fuzz::Mutator mutator;
  const std::uint64_t seeds = types.size();  // the first case of each type is its populated seed
  pb::util::DefaultFieldComparator comparator;
  comparator.set_treat_nan_as_equal(true);
  auto make = [&](Rng& rng, std::uint64_t i) -> ProtoCase {
    ProtoCase c;
    c.type = static_cast<int>(i < seeds ? i : fuzz::below(rng, types.size()));
    if (i < seeds) {
      c.bytes = corpus[c.type][1];
      return c;
    }
    if (fuzz::chance(rng, 10)) {
      c.bytes = mutator.random(rng, 2048);
      return c;
    }
    c.bytes = corpus[c.type][fuzz::below(rng, corpus[c.type].size())];
    mutator.mutate(rng, c.bytes, fuzz::chance(rng, 50) ? corpus[c.type] : all, 16384);
    return c;
  };
  auto check = [&](const ProtoCase& c, fuzz::Verdict& v) -> Outcome {
    std::unique_ptr<pb::Message> m(prototypes[c.type]->New());
    if (!m->ParseFromString(c.bytes)) return Outcome::kRejected;
    const std::string once = serializeDeterministic(*m);
    std::unique_ptr<pb::Message> back(prototypes[c.type]->New());
    if (!back->ParseFromString(once)) {
      v.fail("the re-serialised message does not parse");
      return Outcome::kAccepted;
    }
    pb::util::MessageDifferencer differ;
    differ.set_field_comparator(&comparator);
    std::string diff;
    differ.ReportDifferencesToString(&diff);
    if (!differ.Compare(*m, *back)) v.fail("parse(serialize(m)) != m: " + diff.substr(0, 2000));
    if (serializeDeterministic(*back) != once) v.fail("serialize(parse(serialize(m))) != serialize(m)");
    return Outcome::kAccepted;
  };
  const auto r = fuzz::runFuzz<ProtoCase>(
      "RequestMessagesParse", 1000000, seeds, make, check,
      [](const ProtoCase& c) { return std::string(1, static_cast<char>(c.type)) + c.bytes; },
      [&](const ProtoCase& c) { return types[c.type]->name() + " from " + fuzz::hexPreview(c.bytes); });
  pb::SetLogHandler(previous);
  if (!fuzz::onlyIteration()) {
    EXPECT_GE(r.accepted, seeds) << "the valid seeds must parse";
    EXPECT_GT(r.rejected, 0u);
  }
}

}  // namespace
}  // namespace sglc
