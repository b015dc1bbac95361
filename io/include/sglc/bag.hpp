// Recorded robot data: rosbag2 (MCAP storage, or SQLite .db3 storage with metadata.yaml) and ROS 1 bags
// (format 2.0) read message by message. A bag is opened once, lists its topics, and hands out each message's bytes on
// request, so a long drive is never held in memory. Every failure throws InputError naming the file (and the record or
// message where it went wrong); nothing in a bag is trusted before it is checked.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace sglc {

enum class MessageEncoding { kCdr, kRos1 };

struct BagTopic {
  std::string name;  // "/points"
  std::string type;  // "sensor_msgs/msg/PointCloud2" (ROS 1 types are named as in ROS 2: pkg/msg/Name)
  MessageEncoding encoding = MessageEncoding::kCdr;
  std::uint64_t messages = 0;
};

// Where one message is; `index` counts the topic's messages from 0 in log-time order.
struct BagMessage {
  std::size_t topic = 0;          // into Bag::topics()
  std::uint64_t log_time_ns = 0;  // when it was recorded
  std::uint64_t index = 0;
  std::uint32_t part = 0;                       // the file of a split rosbag2 directory
  std::uint64_t where = 0, slot = 0, size = 0;  // the storage's own (container record, offset, length)
  // The message's first bytes (up to 16), read when the bag was opened: enough for a ROS header's stamp, so
  // a drive can be laid out without reading every cloud twice.
  std::array<std::uint8_t, 16> head{};
  std::uint8_t head_size = 0;
};

class Bag {
 public:
  virtual ~Bag() = default;
  const std::string& path() const { return path_; }
  const std::vector<BagTopic>& topics() const { return topics_; }
  // The topic named so, or InputError listing the topics there are (with their types).
  std::size_t topic(const std::string& name) const;
  // Every message of the topics named (indices into topics()), in log-time order (ties: as stored).
  std::vector<BagMessage> messages(const std::vector<std::size_t>& topics) const;
  // The message's serialized bytes.
  virtual std::vector<std::uint8_t> read(const BagMessage& m) = 0;
  // "BAG: topic /points, message 12" for error messages.
  std::string where(const BagMessage& m) const;

 protected:
  explicit Bag(std::string path) : path_(std::move(path)) {}
  std::string path_;
  std::vector<BagTopic> topics_;
  std::vector<BagMessage> messages_;  // every message, as listed when opened (index filled by finish())
  // Numbers each topic's messages in log-time order; storages call it once their messages are listed.
  void finish();
};

// True when `path` looks like a bag: an MCAP file or ROS 1 bag (by their magic), a .db3 or .bag file, or a
// directory with a rosbag2 metadata.yaml.
bool isBag(const std::string& path);
// Opens an MCAP file, a ROS 1 .bag, a .db3 file, or a rosbag2 directory (its metadata.yaml names the storage
// and files).
std::unique_ptr<Bag> openBag(const std::string& path);

}  // namespace sglc
