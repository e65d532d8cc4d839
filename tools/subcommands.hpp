#pragma once
// stereoctl subcommands that live in their own files (one file per subcommand, as git's builtin/).
#include <string>

namespace CLI {
class App;
}

namespace stereod::tools {

/// `stereoctl devices`: every camera each driver finds and what it can do.
void add_devices_command(CLI::App &app);
/// `stereoctl export`: a recording to PNG pairs (the `folder` layout) or a KITTI raw-data drive folder.
void add_export_command(CLI::App &app);

} // namespace stereod::tools
