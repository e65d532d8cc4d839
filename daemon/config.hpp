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
	int worker_nice = 0;	       ///< processing threads run this much nicer than capture
	bool warm_up = true;	       ///< workers run the stages on made-up frames before capture starts
};

struct OutputConfig {
	std::string socket = "/tmp/stereod.sock";
	int socket_mode = 0660;
	int client_queue = 256;		  ///< messages buffered per client before its oldest are dropped
	int client_max_input = 4096;	  ///< bytes a client may send before it is dropped as misbehaving
	int client_queue_bytes = 8 << 20; ///< bytes queued per client before its oldest messages are dropped
	int max_clients = 64;		  ///< clients served at once; more are refused with an error line
	double status_interval_s = 1.0;
	std::string socket_group;	       ///< group owning the socket file; empty: the daemon's own
	std::vector<std::string> allow_users;  ///< who may read (names or uids); with allow_groups empty: anyone
	std::vector<std::string> allow_groups; ///< members of these groups may read (names or gids)
};

struct LogConfig {
	std::string level = "info";
};

struct CalibrationConfig {
	/// OpenCV stereo calibration (YAML/XML/JSON, drivers/calibration_file.hpp); empty: the source's own.
	std::string file;
};

struct RecordConfig {
	std::string path;      ///< live recording (.srec) beside the stream; empty: off
	int buffer_frames = 8; ///< frames copied and waiting for the disk at most
	bool sync = false;     ///< force each frame to the disk before the next (slower, power-cut safe)
	bool images = false;   ///< MCAP: JPEG images beside the raw frames (Foxglove shows them)
	bool results = true;   ///< MCAP: the processed results too
};

/// Results on DDS as ROS 2 messages (daemon/dds/dds_publisher.hpp, docs/ros2.md).
struct DdsConfig {
	bool enabled = false;
	int domain = 0;			       ///< DDS domain id (ROS_DOMAIN_ID on the ROS 2 side)
	std::string name = "front";	       ///< this board's name in the topic names
	std::string qos = "reliable";	       ///< "reliable" (ROS 2's default) or "sensor_data"
	std::string frame_id = "odom";	       ///< Odometry's header.frame_id: the first frame's camera
	std::string child_frame_id = "camera"; ///< the camera (left rectified, optical axes): points, groups, twist
	bool operator==(const DdsConfig &) const = default;
};

struct DaemonConfig {
	drivers::SourceConfig source;
	CalibrationConfig calibration;
	PipelineConfig pipeline;
	vision::MotionParams motion;
	OutputConfig output;
	RecordConfig record;
	DdsConfig dds;
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
/// `text` cut to `limit` characters with its full length said, for echoing user input in messages.
std::string describe_cut(const std::string &text, size_t limit = 80);
/// A complete, commented config file holding every option at its default.
std::string default_config_text();
/// The options (`section.key`) whose values differ between two configs, in the config file's order.
std::vector<std::string> changed_options(const DaemonConfig &a, const DaemonConfig &b);

} // namespace stereod::daemon
