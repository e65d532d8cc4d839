#pragma once
// The two ways to run the pipeline: as the daemon (a live source, the socket, status messages, signals,
// systemd notification) and as a batch job (a file source, as fast as possible, NDJSON to a file).
#include <functional>
#include <string>

#include "daemon/config.hpp"

namespace stereod::daemon {

/// Runs until SIGTERM/SIGINT (drains, returns 0) or until a finite source ends. On SIGHUP, `reload` gives
/// the configuration to switch to (it throws ConfigError for one that does not load); empty: SIGHUP is
/// logged and ignored.
int run_daemon(const DaemonConfig &config, const std::function<DaemonConfig()> &reload = {});

struct BatchOptions {
	std::string output;    ///< NDJSON file, "-" for standard output; MCAP for a .mcap path (docs/mcap.md)
	bool images = false;   ///< MCAP output: the images too, as JPEG (foxglove.CompressedImage)
	std::string truth_dir; ///< when set and the source knows the truth: masks and truth.ndjson go here
	bool progress = true;  ///< a progress bar when standard error is a terminal
};

/// Processes every frame of config.source with blocking hand-off (nothing dropped). Returns 0 on success.
int run_batch(DaemonConfig config, const BatchOptions &options);

/// Maps a --format name (or "auto", guessing from the path) to a driver name. Throws ConfigError.
std::string driver_for_format(const std::string &format, const std::string &path);

/// Workers to use when the config says 0.
size_t default_workers();

} // namespace stereod::daemon
