#pragma once
// Shared by the stereoctl subcommands: opening a source the way stereod does, and reading NDJSON results.
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "daemon/config.hpp"
#include "drivers/source.hpp"

namespace stereod::tools {

/// The source options every subcommand that reads frames accepts.
struct SourceOptions {
	std::string config_path;
	std::vector<std::string> overrides;
	std::string input; ///< path; empty = the config's source
	std::string format = "auto";
	bool realtime = false; ///< pace generated sources like a camera
};

daemon::DaemonConfig load_config(const SourceOptions &options);
std::unique_ptr<drivers::FrameSource> open_source(const SourceOptions &options);

/// Reads frame messages from an NDJSON file, or the results channel of an MCAP file (`stereod process --output
/// X.mcap`, a live MCAP recording), keyed by seq. Other message types are skipped.
std::map<uint64_t, FrameResult> read_results(const std::string &path);

} // namespace stereod::tools
