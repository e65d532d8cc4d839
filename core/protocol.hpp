#pragma once
// The wire form of results: newline-delimited JSON, documented in docs/protocol.md. Pure functions: they
// build strings and parse them, the socket and file writers live elsewhere.
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>

#include <nlohmann/json_fwd.hpp>

#include "core/result.hpp"

namespace stereod::protocol {

inline constexpr int kVersion = 1;

/// One `frame` message, without the trailing newline.
std::string frame_message(const FrameResult &result);
/// A JSON Schema (draft 2020-12) of the `frame` message, for containers that carry a schema beside the data
/// (MCAP's `jsonschema` encoding, docs/mcap.md). Field meanings are in docs/protocol.md.
std::string_view frame_json_schema();

/// Parses a `frame` message back (used by the tools: eval, render, watch). Throws on malformed input.
FrameResult parse_frame_message(const nlohmann::json &message);

struct LatencySummary {
	double p50_ms = 0;
	double p90_ms = 0;
	double p99_ms = 0;
	double max_ms = 0;
	size_t samples = 0;
};

struct StatusReport {
	int64_t t_host_ns = 0;
	double uptime_s = 0;
	std::string source;
	std::string source_state; ///< "streaming", "reconnecting", "finished"
	double capture_fps = 0;
	double publish_fps = 0;
	uint64_t frames_captured = 0;
	uint64_t frames_published = 0;
	std::map<std::string, uint64_t> drops; ///< counter name -> frames (or messages) lost there
	std::map<std::string, int64_t> device; ///< the capture device's own statistics (cameras only)
	LatencySummary capture_to_publish;
	size_t clients = 0;
	/// Stereo sources: the calibration's health (running means over ~30 frames).
	struct StereoHealth {
		uint64_t frames = 0;
		double row_diff_px = 0;
		double outside_band_fraction = 0;
		bool drifted = false;
	};
	std::optional<StereoHealth> stereo;
	/// Live recording (`[record] path`), when on.
	struct Recording {
		std::string path;
		std::string state; ///< "recording", "failed" (error says why; the stream goes on), "stopped"
		std::string error;
		uint64_t frames = 0; ///< complete frames in the file
		uint64_t bytes = 0;
		uint64_t dropped = 0; ///< frames not recorded: the disk was slower than the camera
	};
	std::optional<Recording> recording;
	/// Publishing on DDS (`[dds] enabled`), when on.
	struct Dds {
		std::string name;
		int domain = 0;
		uint64_t frames_published = 0;
		uint64_t frames_dropped = 0; ///< replaced while waiting: DDS slower than the pipeline
		uint64_t write_errors = 0;
		double publish_ms_mean = 0; ///< converting and writing one frame's three messages
		double publish_ms_max = 0;
	};
	std::optional<Dds> dds;
};

std::string status_message(const StatusReport &status);

/// Told to one client after its queue overflowed: how many of its messages were discarded.
std::string lag_message(int64_t t_host_ns, uint64_t dropped_total, uint64_t dropped_since_last);

/// Sent to a client that is refused (client limit, out of descriptors, not allowed) just before it is closed.
std::string error_message(int64_t t_host_ns, const std::string &what);

/// The first line every client receives.
std::string hello_message(int64_t t_host_ns, const std::string &source, int width, int height);

} // namespace stereod::protocol
