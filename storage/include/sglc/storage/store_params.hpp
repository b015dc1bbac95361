// The map store's settings (StoreOptions, except the file path) in the settings registry: the `storage:`
// section of the server's configuration.
#pragma once

#include "sglc/params.hpp"
#include "sglc/storage/map_store.hpp"

namespace sglc::storage {

const params::Table<StoreOptions>& storeParams();

}  // namespace sglc::storage
