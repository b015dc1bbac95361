// Operating the store: online backups, the integrity check, statistics.
#pragma once

#include <string>

#include "store_core.hpp"

namespace sglc::storage::admin {

void backup(const StoreCore& core, const std::string& dest);
std::string integrityCheck(const StoreCore& core);
Stats stats(const StoreCore& core, const std::string& map);

}  // namespace sglc::storage::admin
