#pragma once
// Registration hooks, one per driver family; SourceRegistry::with_builtin_drivers() calls them all.
#include "drivers/source.hpp"

namespace stereod::drivers {

void register_sim(SourceRegistry &registry);
void register_replay(SourceRegistry &registry);	  ///< the project's own recordings
void register_datasets(SourceRegistry &registry); ///< video, kitti, euroc, tum, folder
void register_aravis(SourceRegistry &registry);	  ///< GigE Vision / USB3 Vision cameras
void register_v4l2(SourceRegistry &registry);	  ///< Video4Linux2 devices
void register_dc1394(SourceRegistry &registry);	  ///< FireWire Bumblebee2 / XB3

} // namespace stereod::drivers
