#pragma once
// The daemon's configuration: a TOML file (documented in docs/configuration.md, every option with its
// default in config/stereod.toml), optionally overridden by `--set section.key=value`. Unknown sections
// and keys, wrong types and out-of-range values are errors that name the file, the line and the key.
#include <stdexcept>
#include <string>
#include <vector>

#include "core/vision/motion_stages.hpp"
#include "drivers/source.hpp"

namespace stereod::daemon {

struct PipelineConfig {
	int workers = 0;	       ///< 0 = one per core
	int ring_capacity = 8;	       ///< frames between capture and processing
	std::string overflow = "auto"; ///< auto | drop-oldest | block ("auto": drop-oldest for live sources)
};

struct OutputConfig {
	std::string socket = "/tmp/stereod.sock";
	int socket_mode = 0660;
	int client_queue = 256;	     ///< messages buffered per client before its oldest are dropped
	int client_max_input = 4096; ///< bytes a client may send before it is dropped as misbehaving
	double status_interval_s = 1.0;
};

struct LogConfig {
	std::string level = "info";
};

struct DaemonConfig {
	drivers::SourceConfig source;
	PipelineConfig pipeline;
	vision::MotionParams motion;
	OutputConfig output;
	LogConfig log;
};

class ConfigError : public std::runtime_error
{
public:
	using std::runtime_error::runtime_error;
};

/// Reads `path` over the defaults. Throws ConfigError("path:line: key: what is wrong").
void load_config_file(const std::string &path, DaemonConfig &config);
/// Applies one `section.key=value` override (value in TOML syntax; bare words are taken as strings).
void apply_override(const std::string &assignment, DaemonConfig &config);
/// Checks the constraints that span several keys (eq. 4: alpha + beta + gamma = 1).
void validate(const DaemonConfig &config, const std::string &origin);
/// A complete, commented config file holding every option at its default.
std::string default_config_text();

} // namespace stereod::daemon
