#include "connection_slots.hpp"

namespace sglc::server {

std::optional<ConnectionSlots::Id> ConnectionSlots::oldestWaiting(const std::string* peer) const {
  for (const auto& [id, h] : held_)
    if (h.waiting && (peer == nullptr || h.peer == *peer)) return id;
  return std::nullopt;
}

std::optional<ConnectionSlots::Admission> ConnectionSlots::admit(const std::string& peer) {
  Admission admission;
  const auto it = per_peer_.find(peer);
  if (it != per_peer_.end() && it->second >= max_per_peer_) {
    const auto victim = oldestWaiting(&peer);
    if (!victim) return std::nullopt;
    admission.evicted.push_back(*victim);
    leave(*victim);
  }
  if (open() >= max_total_) {
    const auto victim = oldestWaiting(nullptr);
    if (!victim) return std::nullopt;
    admission.evicted.push_back(*victim);
    leave(*victim);
  }
  admission.id = next_++;
  held_.emplace(admission.id, Held{peer, true});
  ++per_peer_[peer];
  return admission;
}

void ConnectionSlots::requestReceived(Id id) {
  if (auto it = held_.find(id); it != held_.end()) it->second.waiting = false;
}

void ConnectionSlots::leave(Id id) {
  const auto it = held_.find(id);
  if (it == held_.end()) return;
  if (auto p = per_peer_.find(it->second.peer); p != per_peer_.end() && --p->second <= 0) per_peer_.erase(p);
  held_.erase(it);
}

}  // namespace sglc::server
