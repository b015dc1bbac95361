// Which connections a small HTTP endpoint keeps: at most max_per_peer per peer and max_total in all. A
// newcomer that finds no free slot takes the one of the oldest connection still waiting for its request
// (idle, slow, or one of many addresses holding slots: a scraper sends its request at once, so it is never the
// oldest waiting); only when every slot is busy answering is the newcomer refused. Plain data, one thread.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace sglc::server {

class ConnectionSlots {
 public:
  using Id = std::uint64_t;

  ConnectionSlots(int max_total, int max_per_peer) : max_total_(max_total), max_per_peer_(max_per_peer) {}

  struct Admission {
    Id id = 0;
    std::vector<Id> evicted;  // gone from the slots: their owners close them
  };
  // Admits a connection from `peer` (any key: the caller decides what one peer is), or nullopt: refused.
  std::optional<Admission> admit(const std::string& peer);
  // Its request has come: it is answered now, and no longer evicted.
  void requestReceived(Id id);
  // It is gone (closed, answered, timed out). Ids not (or no longer) held are ignored.
  void leave(Id id);

  int open() const { return static_cast<int>(held_.size()); }

 private:
  struct Held {
    std::string peer;
    bool waiting = true;  // for its request
  };
  // The oldest connection waiting for its request, of `peer` (or of anyone, when null).
  std::optional<Id> oldestWaiting(const std::string* peer) const;

  const int max_total_, max_per_peer_;
  Id next_ = 1;
  std::map<Id, Held> held_;  // by id: in order of arrival
  std::map<std::string, int> per_peer_;
};

}  // namespace sglc::server
