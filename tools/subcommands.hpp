#pragma once
// stereoctl subcommands that live in their own files (one file per subcommand, as git's builtin/).
#include <cstddef>
#include <string>

namespace CLI {
class App;
}

namespace stereod::tools {

/// `stereoctl devices`: every camera each driver finds and what it can do.
void add_devices_command(CLI::App &app);
/// `stereoctl calibrate`: a stereo calibration from chessboard pairs (OpenCV YAML/XML for calibration.file).
void add_calibrate_command(CLI::App &app);
/// `stereoctl info`: what a recording (.srec or MCAP) holds, every record checked.
void add_info_command(CLI::App &app);
/// `stereoctl fleet`: every stereod on a DDS domain, one line per board, found by DDS discovery.
void add_fleet_command(CLI::App &app);
/// `stereoctl export`: a recording to PNG pairs (the `folder` layout) or a KITTI raw-data drive folder.
void add_export_command(CLI::App &app);
/// `stereoctl map`: the static scene, movers left out, as a PLY point cloud (issue 15's static map).
void add_map_command(CLI::App &app);
/// `stereoctl reference`: moving-pixel masks for footage from a still camera (a truth folder for eval).
void add_reference_command(CLI::App &app);

/// `stereoctl eval --poses`: the estimated trajectory against TUM or KITTI ground truth (ATE, RPE, drift).
struct TrajectoryEvalOptions {
	std::string results; ///< NDJSON from stereod process
	std::string poses;   ///< TUM file, KITTI poses file, or a --truth-dir folder (its poses.tum)
	std::string name = "run";
	size_t delta = 1;	///< RPE over this many frames
	size_t window = 10;	///< drift windows, frames
	double max_dt_s = 0.02; ///< TUM association tolerance
	bool json = false;
	std::string write_estimate; ///< also write the estimate as TUM here
};
int eval_trajectory(const TrajectoryEvalOptions &options);

} // namespace stereod::tools
