// The PostgreSQL map database's schema: checked on open (ours, not newer) and migrated forward.
#pragma once

#include <string>

#include "postgres.hpp"

namespace sglc::storage::pg {

// Schema version this build writes in PostgreSQL (numbered apart from the SQLite file's).
inline constexpr int kSchemaVersion = 5;

// Creates or migrates our tables in the connection's current schema, one transaction per step, under an
// advisory lock so that replicas opening together migrate once. Throws kCorrupt for a database that holds
// other tables but not ours, kNewerSchema for one written by a newer build. `url` (redacted) names it.
void openSchema(const Conn& db, const std::string& url);

}  // namespace sglc::storage::pg
