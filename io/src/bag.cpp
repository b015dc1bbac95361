#include "sglc/bag.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>

#include "db3_bag.hpp"
#include "mcap_bag.hpp"
#include "ros1_bag.hpp"
#include "sglc/types.hpp"

namespace sglc {

static_assert(std::endian::native == std::endian::little, "the bag readers read little-endian fields by memcpy");

namespace fs = std::filesystem;

std::size_t Bag::topic(const std::string& name) const {
  for (std::size_t i = 0; i < topics_.size(); ++i)
    if (topics_[i].name == name) return i;
  std::string there;
  for (const auto& t : topics_)
    there += (there.empty() ? "" : ", ") + t.name + " (" + t.type + ", " + std::to_string(t.messages) + " messages)";
  throw InputError(path_ + ": no topic " + name + "; its topics: " + (there.empty() ? "none" : there));
}

std::vector<BagMessage> Bag::messages(const std::vector<std::size_t>& topics) const {
  std::vector<bool> wanted(topics_.size(), false);
  for (auto t : topics) wanted.at(t) = true;
  std::vector<BagMessage> out;
  for (const auto& m : messages_)
    if (wanted[m.topic]) out.push_back(m);
  return out;
}

std::string Bag::where(const BagMessage& m) const {
  return path_ + ": topic " + topics_.at(m.topic).name + ", message " + std::to_string(m.index);
}

void Bag::finish() {
  std::stable_sort(messages_.begin(), messages_.end(),
                   [](const BagMessage& a, const BagMessage& b) { return a.log_time_ns < b.log_time_ns; });
  std::vector<std::uint64_t> count(topics_.size(), 0);
  for (auto& m : messages_) m.index = count[m.topic]++;
}

namespace {

bool hasMcapMagic(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  char magic[8] = {};
  f.read(magic, 8);
  return f.gcount() == 8 && std::memcmp(magic, "\x89MCAP0\r\n", 8) == 0;
}

bool hasRos1Magic(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  char magic[13] = {};
  f.read(magic, 13);
  return f.gcount() == 13 && std::memcmp(magic, "#ROSBAG V2.0\n", 13) == 0;
}

std::unique_ptr<Bag> openFile(const std::string& path) {
  if (hasMcapMagic(path)) return std::make_unique<McapBag>(path);
  if (hasRos1Magic(path) || fs::path(path).extension() == ".bag") return std::make_unique<Ros1Bag>(path);
  if (fs::path(path).extension() == ".db3") return std::make_unique<Db3Bag>(path);
  throw InputError(path + ": not a bag (neither MCAP, a rosbag2 .db3 file nor a ROS 1 .bag)");
}

// A rosbag2 directory: metadata.yaml names its storage and files (several when the recording was split); their
// topics are merged by name and their messages put in one log-time order.
class SplitBag final : public Bag {
 public:
  explicit SplitBag(const std::string& dir) : Bag(dir) {
    const fs::path meta = fs::path(dir) / "metadata.yaml";
    std::vector<std::string> files;
    try {
      const YAML::Node info = YAML::LoadFile(meta.string())["rosbag2_bagfile_information"];
      if (!info) throw InputError(meta.string() + ": no rosbag2_bagfile_information");
      const auto storage = info["storage_identifier"].as<std::string>("");
      if (storage != "mcap" && storage != "sqlite3")
        throw InputError(meta.string() + ": storage '" + storage + "'; this reader takes mcap and sqlite3");
      for (const auto& f : info["relative_file_paths"]) files.push_back(f.as<std::string>());
    } catch (const YAML::Exception& e) {
      throw InputError(meta.string() + ": " + e.what());
    }
    if (files.empty()) throw InputError(meta.string() + ": relative_file_paths lists no file");
    std::map<std::string, std::size_t> by_name;
    for (const auto& rel : files) {
      if (fs::path(rel).is_absolute() || rel.find("..") != std::string::npos)
        throw InputError(meta.string() + ": file '" + rel + "' is not inside the bag's directory");
      parts_.push_back(openFile((fs::path(dir) / rel).string()));
      const Bag& part = *parts_.back();
      std::vector<std::size_t> topic_of(part.topics().size());
      for (std::size_t t = 0; t < part.topics().size(); ++t) {
        const auto& pt = part.topics()[t];
        auto [it, fresh] = by_name.emplace(pt.name, topics_.size());
        if (fresh) {
          topics_.push_back(pt);
          topics_.back().messages = 0;
        }
        topic_of[t] = it->second;
      }
      std::vector<std::size_t> all(part.topics().size());
      for (std::size_t t = 0; t < all.size(); ++t) all[t] = t;
      for (auto m : part.messages(all)) {
        m.topic = topic_of[m.topic];
        m.part = static_cast<std::uint32_t>(parts_.size() - 1);
        ++topics_[m.topic].messages;
        messages_.push_back(m);
      }
    }
    finish();
  }

  std::vector<std::uint8_t> read(const BagMessage& m) override {
    Bag& part = *parts_.at(m.part);
    BagMessage local = m;
    local.topic = part.topic(topics_.at(m.topic).name);
    return part.read(local);
  }

 private:
  std::vector<std::unique_ptr<Bag>> parts_;
};

}  // namespace

bool isBag(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) return fs::is_regular_file(fs::path(path) / "metadata.yaml", ec);
  return fs::is_regular_file(path, ec) &&
         (hasMcapMagic(path) || hasRos1Magic(path) || fs::path(path).extension() == ".db3" ||
          fs::path(path).extension() == ".bag");
}

std::unique_ptr<Bag> openBag(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    if (!fs::is_regular_file(fs::path(path) / "metadata.yaml", ec))
      throw InputError(path + ": a directory without metadata.yaml is not a rosbag2 bag");
    return std::make_unique<SplitBag>(path);
  }
  if (!fs::is_regular_file(path, ec))
    throw InputError(path + (fs::exists(path, ec) ? ": not a regular file" : ": no such file"));
  return openFile(path);
}

}  // namespace sglc
