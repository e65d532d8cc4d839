#pragma once
// Registration hooks, one per driver family; SourceRegistry::with_builtin_drivers() calls them all.
#include "drivers/source.hpp"

namespace stereod::drivers {

void register_sim(SourceRegistry &registry);
void register_replay(SourceRegistry &registry);	  ///< the project's own recordings
void register_datasets(SourceRegistry &registry); ///< video, kitti, euroc, tum, folder

} // namespace stereod::drivers
