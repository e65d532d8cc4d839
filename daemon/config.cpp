#include "daemon/config.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <utility>

#include <sys/un.h>

#include <toml.hpp>

#include "core/vision/prior_model.hpp"

namespace stereod::daemon {

std::string describe_cut(const std::string &text, size_t limit)
{
	if (text.size() <= limit)
		return text;
	return text.substr(0, limit) + "... (" + std::to_string(text.size()) + " bytes)";
}

namespace {

using Value = toml::value;

/// One option: where it lives, what it means, how to set it from TOML and print its default.
struct Option {
	std::string section;
	std::string key;
	std::string help;
	std::function<void(const Value &, DaemonConfig &)> set; ///< throws std::invalid_argument with the reason
	std::function<std::string(const DaemonConfig &)> show;
};

std::string format_double(double v)
{
	std::ostringstream out;
	out << v;
	std::string s = out.str();
	if (s.find_first_of(".e") == std::string::npos)
		s += ".0";
	return s;
}

template <typename Access>
Option number(std::string section, std::string key, std::string help, Access access, double lo, double hi)
{
	using Member = std::remove_reference_t<decltype(access(std::declval<DaemonConfig &>()))>;
	Option o{std::move(section), std::move(key), std::move(help), nullptr, nullptr};
	o.set = [access, lo, hi](const Value &v, DaemonConfig &c) {
		double x = 0;
		if (v.is_integer())
			x = static_cast<double>(v.as_integer());
		else if (v.is_floating() && std::is_floating_point_v<Member>)
			x = v.as_floating();
		else
			throw std::invalid_argument(std::is_floating_point_v<Member> ? "must be a number"
										     : "must be an integer");
		if (!(x >= lo && x <= hi)) {
			std::ostringstream msg;
			msg << "must be between " << lo << " and " << hi << " (got " << x << ")";
			throw std::invalid_argument(msg.str());
		}
		access(c) = static_cast<Member>(x);
	};
	o.show = [access](const DaemonConfig &c) {
		if constexpr (std::is_floating_point_v<Member>)
			return format_double(static_cast<double>(access(const_cast<DaemonConfig &>(c))));
		else
			return std::to_string(access(const_cast<DaemonConfig &>(c)));
	};
	return o;
}

template <typename Access>
Option boolean(std::string section, std::string key, std::string help, Access access)
{
	Option o{std::move(section), std::move(key), std::move(help), nullptr, nullptr};
	o.set = [access](const Value &v, DaemonConfig &c) {
		if (!v.is_boolean())
			throw std::invalid_argument("must be true or false");
		access(c) = v.as_boolean();
	};
	o.show = [access](const DaemonConfig &c) {
		return std::string(access(const_cast<DaemonConfig &>(c)) ? "true" : "false");
	};
	return o;
}

template <typename Access>
Option text(std::string section, std::string key, std::string help, Access access,
	    std::vector<std::string> choices = {})
{
	Option o{std::move(section), std::move(key), std::move(help), nullptr, nullptr};
	o.set = [access, choices](const Value &v, DaemonConfig &c) {
		if (!v.is_string())
			throw std::invalid_argument("must be a string");
		const std::string s = v.as_string();
		if (!choices.empty() && std::find(choices.begin(), choices.end(), s) == choices.end()) {
			std::string list;
			for (const auto &choice : choices)
				list += (list.empty() ? "" : ", ") + choice;
			throw std::invalid_argument("must be one of " + list + " (got '" + s + "')");
		}
		access(c) = s;
	};
	o.show = [access](const DaemonConfig &c) {
		return "\"" + std::string(access(const_cast<DaemonConfig &>(c))) + "\"";
	};
	return o;
}

template <typename Access>
Option text_list(std::string section, std::string key, std::string help, Access access)
{
	Option o{std::move(section), std::move(key), std::move(help), nullptr, nullptr};
	o.set = [access](const Value &v, DaemonConfig &c) {
		if (!v.is_array())
			throw std::invalid_argument("must be an array of strings, e.g. [\"Name=value\"]");
		std::vector<std::string> items;
		for (const auto &item : v.as_array()) {
			if (!item.is_string())
				throw std::invalid_argument("must be an array of strings");
			items.push_back(item.as_string());
		}
		access(c) = std::move(items);
	};
	o.show = [access](const DaemonConfig &c) {
		std::string out = "[";
		for (const auto &item : access(const_cast<DaemonConfig &>(c)))
			out += (out.size() > 1 ? ", " : "") + toml::format(Value(item));
		return out + "]";
	};
	return o;
}

/// An enum option: the file names one of `names` (in the order the error message lists them).
template <typename Access, typename Enum>
Option enumeration(std::string section, std::string key, std::string help, Access access,
		   std::vector<std::pair<std::string, Enum>> names)
{
	Option o{std::move(section), std::move(key), std::move(help), nullptr, nullptr};
	o.set = [access, names](const Value &v, DaemonConfig &c) {
		const std::string s = v.is_string() ? std::string(v.as_string()) : std::string();
		std::string list;
		for (const auto &[name, value] : names) {
			if (name == s) {
				access(c) = value;
				return;
			}
			list += (list.empty() ? "" : ", ") + name;
		}
		throw std::invalid_argument("must be one of " + list);
	};
	o.show = [access, names](const DaemonConfig &c) {
		const Enum current = access(const_cast<DaemonConfig &>(c));
		for (const auto &[name, value] : names)
			if (value == current)
				return "\"" + name + "\"";
		return std::string("\"?\"");
	};
	return o;
}

const std::vector<Option> &options()
{
	static const std::vector<Option> all = [] {
		std::vector<Option> o;
		// [source]
		o.push_back(text(
			"source", "driver",
			"capture driver: sim | aravis | v4l2 | dc1394 | replay | video | kitti | euroc | tum | folder",
			[](DaemonConfig &c) -> std::string & { return c.source.driver; },
			{"sim", "aravis", "v4l2", "dc1394", "replay", "video", "kitti", "euroc", "tum", "folder"}));
		o.push_back(text("source", "path", "file or folder for the file drivers",
				 [](DaemonConfig &c) -> std::string & { return c.source.path; }));
		o.push_back(enumeration(
			"source", "rate", "file sources: recorded (original spacing) | fast | step (Enter per frame)",
			[](DaemonConfig &c) -> drivers::ReplayRate & { return c.source.rate; },
			std::vector<std::pair<std::string, drivers::ReplayRate>>{
				{"recorded", drivers::ReplayRate::Recorded},
				{"fast", drivers::ReplayRate::Fast},
				{"step", drivers::ReplayRate::Step}}));
		o.push_back(boolean("source", "realtime", "pace generated sources (sim) at their frame rate",
				    [](DaemonConfig &c) -> bool & { return c.source.realtime; }));
		o.push_back(number(
			"source", "fps", "frame rate for inputs that state none (folder pairs); 0 = theirs",
			[](DaemonConfig &c) -> double & { return c.source.fps; }, 0, 1000));
		// [calibration]
		o.push_back(text("calibration", "file",
				 "OpenCV stereo calibration (M1 D1 M2 D2 R T [R1 R2 P1 P2], YAML/XML, e.g. from "
				 "stereoctl calibrate): both eyes are rectified with it; empty = the source's own",
				 [](DaemonConfig &c) -> std::string & { return c.calibration.file; }));
		// [aravis]
		o.push_back(text("aravis", "left", "camera id: Vendor-Model-Serial, IP address or user id",
				 [](DaemonConfig &c) -> std::string & { return c.source.aravis.left; }));
		o.push_back(text("aravis", "right", "second camera; empty: the left one carries both eyes (layout)",
				 [](DaemonConfig &c) -> std::string & { return c.source.aravis.right; }));
		o.push_back(text("aravis", "layout", "pair | interleaved16 | side_by_side | top_bottom",
				 [](DaemonConfig &c) -> std::string & { return c.source.aravis.layout; },
				 {"pair", "interleaved16", "side_by_side", "top_bottom"}));
		o.push_back(number(
			"aravis", "frame_rate", "AcquisitionFrameRate; 0 = the camera's",
			[](DaemonConfig &c) -> double & { return c.source.aravis.frame_rate; }, 0, 10000));
		o.push_back(number(
			"aravis", "width", "Width; 0 = the camera's",
			[](DaemonConfig &c) -> int & { return c.source.aravis.width; }, 0, 65535));
		o.push_back(number(
			"aravis", "height", "Height; 0 = the camera's",
			[](DaemonConfig &c) -> int & { return c.source.aravis.height; }, 0, 65535));
		o.push_back(text("aravis", "pixel_format",
				 "PixelFormat (Mono8, Mono16, BayerRG8, RGB8, ...); empty = the camera's",
				 [](DaemonConfig &c) -> std::string & { return c.source.aravis.pixel_format; }));
		o.push_back(number(
			"aravis", "exposure_us", "ExposureTime, microseconds; 0 = leave",
			[](DaemonConfig &c) -> double & { return c.source.aravis.exposure_us; }, 0, 1e8));
		o.push_back(number(
			"aravis", "gain_db", "Gain; negative = leave",
			[](DaemonConfig &c) -> double & { return c.source.aravis.gain_db; }, -1, 1000));
		o.push_back(number(
			"aravis", "packet_size", "GigE: GevSCPSPacketSize in bytes; 0 = leave",
			[](DaemonConfig &c) -> int & { return c.source.aravis.packet_size; }, 0, 65535));
		o.push_back(text("aravis", "trigger",
				 "off | software (fired at frame_rate) | a TriggerSource (Line0, ...)",
				 [](DaemonConfig &c) -> std::string & { return c.source.aravis.trigger; }));
		o.push_back(boolean("aravis", "ptp", "enable IEEE 1588 clock sync on the cameras",
				    [](DaemonConfig &c) -> bool & { return c.source.aravis.ptp; }));
		o.push_back(text("aravis", "clock",
				 "pair: shared (one clock, e.g. PTP: skew from device stamps) | per_camera | auto "
				 "(shared if ptp)",
				 [](DaemonConfig &c) -> std::string & { return c.source.aravis.clock; },
				 {"auto", "shared", "per_camera"}));
		o.push_back(number(
			"aravis", "max_skew_ms",
			"pair: frames further apart are unpaired (counted); 0 = a quarter frame period",
			[](DaemonConfig &c) -> double & { return c.source.aravis.max_skew_ms; }, 0, 10000));
		o.push_back(text("aravis", "first_byte",
				 "interleaved16: the eye in byte 0 of each pixel (left | right)",
				 [](DaemonConfig &c) -> std::string & { return c.source.aravis.first_byte; },
				 {"left", "right"}));
		o.push_back(text("aravis", "bayer", "auto (from the pixel format) | none | RGGB | GRBG | GBRG | BGGR",
				 [](DaemonConfig &c) -> std::string & { return c.source.aravis.bayer; },
				 {"auto", "none", "RGGB", "GRBG", "GBRG", "BGGR"}));
		o.push_back(text("aravis", "color", "frame images: auto | mono | bgr",
				 [](DaemonConfig &c) -> std::string & { return c.source.aravis.color; },
				 {"auto", "mono", "bgr"}));
		o.push_back(number(
			"aravis", "buffers", "stream buffers per camera",
			[](DaemonConfig &c) -> int & { return c.source.aravis.buffers; }, 2, 256));
		o.push_back(number(
			"aravis", "no_frame_timeout_s", "a camera silent this long is lost and reconnected",
			[](DaemonConfig &c) -> double & { return c.source.aravis.no_frame_timeout_s; }, 0.1, 3600));
		o.push_back(text_list(
			"aravis", "features", "further GenICam settings, [\"Name=value\", ...]",
			[](DaemonConfig &c) -> std::vector<std::string> & { return c.source.aravis.features; }));
		// [v4l2]
		o.push_back(text("v4l2", "left", "device node",
				 [](DaemonConfig &c) -> std::string & { return c.source.v4l2.left; }));
		o.push_back(text("v4l2", "right", "second device; empty: the left one carries both eyes (layout)",
				 [](DaemonConfig &c) -> std::string & { return c.source.v4l2.right; }));
		o.push_back(text("v4l2", "layout", "pair | side_by_side | top_bottom",
				 [](DaemonConfig &c) -> std::string & { return c.source.v4l2.layout; },
				 {"pair", "side_by_side", "top_bottom"}));
		o.push_back(number(
			"v4l2", "width", "width; 0 = the driver's",
			[](DaemonConfig &c) -> int & { return c.source.v4l2.width; }, 0, 65535));
		o.push_back(number(
			"v4l2", "height", "height; 0 = the driver's",
			[](DaemonConfig &c) -> int & { return c.source.v4l2.height; }, 0, 65535));
		o.push_back(text("v4l2", "pixel_format", "YUYV | GREY | MJPG | ...; empty = the driver's",
				 [](DaemonConfig &c) -> std::string & { return c.source.v4l2.pixel_format; }));
		o.push_back(number(
			"v4l2", "fps", "frame rate (VIDIOC_S_PARM); 0 = the driver's",
			[](DaemonConfig &c) -> double & { return c.source.v4l2.fps; }, 0, 1000));
		o.push_back(text("v4l2", "color", "frame images: mono | bgr",
				 [](DaemonConfig &c) -> std::string & { return c.source.v4l2.color; },
				 {"mono", "bgr"}));
		o.push_back(number(
			"v4l2", "buffers", "mmap buffers per device",
			[](DaemonConfig &c) -> int & { return c.source.v4l2.buffers; }, 2, 32));
		o.push_back(number(
			"v4l2", "max_skew_ms", "pair: frames further apart are unpaired (counted)",
			[](DaemonConfig &c) -> double & { return c.source.v4l2.max_skew_ms; }, 0, 10000));
		o.push_back(number(
			"v4l2", "no_frame_timeout_s", "a device silent this long is lost and reopened",
			[](DaemonConfig &c) -> double & { return c.source.v4l2.no_frame_timeout_s; }, 0.1, 3600));
		o.push_back(text_list(
			"v4l2", "controls", "controls by name, [\"name=value\", ...] (v4l2-ctl -l)",
			[](DaemonConfig &c) -> std::vector<std::string> & { return c.source.v4l2.controls; }));
		// [dc1394]
		o.push_back(text("dc1394", "guid", "camera GUID (hex); empty = the first camera found",
				 [](DaemonConfig &c) -> std::string & { return c.source.dc1394.guid; }));
		o.push_back(text("dc1394", "model", "bumblebee2 | xb3",
				 [](DaemonConfig &c) -> std::string & { return c.source.dc1394.model; },
				 {"bumblebee2", "xb3"}));
		o.push_back(text("dc1394", "sensors", "xb3: wide (outer pair) | narrow (left and middle)",
				 [](DaemonConfig &c) -> std::string & { return c.source.dc1394.sensors; },
				 {"wide", "narrow"}));
		o.push_back(text("dc1394", "first_byte", "the eye in byte 0 of each pixel (left | right)",
				 [](DaemonConfig &c) -> std::string & { return c.source.dc1394.first_byte; },
				 {"left", "right"}));
		o.push_back(text("dc1394", "bayer", "auto (the camera's register) | none | RGGB | GRBG | GBRG | BGGR",
				 [](DaemonConfig &c) -> std::string & { return c.source.dc1394.bayer; },
				 {"auto", "none", "RGGB", "GRBG", "GBRG", "BGGR"}));
		o.push_back(text("dc1394", "color", "frame images: auto | mono | bgr",
				 [](DaemonConfig &c) -> std::string & { return c.source.dc1394.color; },
				 {"auto", "mono", "bgr"}));
		o.push_back(number(
			"dc1394", "frame_rate", "frame rate; 0 = the camera's",
			[](DaemonConfig &c) -> double & { return c.source.dc1394.frame_rate; }, 0, 240));
		// [sim]
		o.push_back(
			text("sim", "scene",
			     "default | static_near | static_far | moving_one | moving_many | toward | walk | rotate",
			     [](DaemonConfig &c) -> std::string & { return c.source.sim.scene; },
			     {"default", "static_near", "static_far", "moving_one", "moving_many", "toward", "walk",
			      "rotate"}));
		o.push_back(number(
			"sim", "seed", "random seed: same seed, same frames",
			[](DaemonConfig &c) -> uint64_t & { return c.source.sim.seed; }, 0, 4e9));
		o.push_back(number(
			"sim", "width", "image width, pixels",
			[](DaemonConfig &c) -> int & { return c.source.sim.width; }, 64, 4096));
		o.push_back(number(
			"sim", "height", "image height, pixels",
			[](DaemonConfig &c) -> int & { return c.source.sim.height; }, 64, 4096));
		o.push_back(number(
			"sim", "fps", "frame rate", [](DaemonConfig &c) -> double & { return c.source.sim.fps; }, 0.1,
			1000));
		o.push_back(boolean("sim", "stereo", "render the right eye too",
				    [](DaemonConfig &c) -> bool & { return c.source.sim.stereo; }));
		o.push_back(number(
			"sim", "baseline_m", "stereo baseline, metres",
			[](DaemonConfig &c) -> double & { return c.source.sim.baseline_m; }, 0.01, 2));
		o.push_back(number(
			"sim", "noise_sigma", "sensor noise, 8-bit units",
			[](DaemonConfig &c) -> double & { return c.source.sim.noise_sigma; }, 0, 50));
		o.push_back(number(
			"sim", "blur_sigma", "optical blur, pixels (0 = none)",
			[](DaemonConfig &c) -> double & { return c.source.sim.blur_sigma; }, 0, 10));
		o.push_back(number(
			"sim", "exposure_variation", "amplitude of slow exposure drift (fraction)",
			[](DaemonConfig &c) -> double & { return c.source.sim.exposure_variation; }, 0, 0.5));
		o.push_back(boolean("sim", "depth", "also emit true depth, like an RGB-D sensor",
				    [](DaemonConfig &c) -> bool & { return c.source.sim.depth; }));
		o.push_back(text("sim", "texture_dir", "folder of photographs; empty = opencv-doc's samples",
				 [](DaemonConfig &c) -> std::string & { return c.source.sim.texture_dir; }));
		o.push_back(number(
			"sim", "frames", "stop after this many frames; 0 = endless",
			[](DaemonConfig &c) -> uint64_t & { return c.source.sim.frames; }, 0, 1e12));
		// [pipeline]
		o.push_back(number(
			"pipeline", "workers", "processing threads; 0 = one per core",
			[](DaemonConfig &c) -> int & { return c.pipeline.workers; }, 0, 256));
		o.push_back(number(
			"pipeline", "ring_capacity", "frames queued between capture and processing",
			[](DaemonConfig &c) -> int & { return c.pipeline.ring_capacity; }, 1, 1024));
		o.push_back(number(
			"pipeline", "worker_nice", "processing threads run this much nicer than capture (0 = same)",
			[](DaemonConfig &c) -> int & { return c.pipeline.worker_nice; }, 0, 19));
		o.push_back(boolean(
			"pipeline", "warm_up",
			"workers run the stages on two made-up frames before capture starts (first frames on time)",
			[](DaemonConfig &c) -> bool & { return c.pipeline.warm_up; }));
		o.push_back(text("pipeline", "overflow", "when processing falls behind: auto | drop-oldest | block",
				 [](DaemonConfig &c) -> std::string & { return c.pipeline.overflow; },
				 {"auto", "drop-oldest", "block"}));
		// [features]
		o.push_back(boolean("features", "enabled", "run feature classification (seed 000)",
				    [](DaemonConfig &c) -> bool & { return c.motion.enabled; }));
		o.push_back(enumeration(
			"features", "detector", "orb (OpenCV) | surf (this project's SURF)",
			[](DaemonConfig &c) -> vision::Detector & { return c.motion.features.detector; },
			std::vector<std::pair<std::string, vision::Detector>>{{"orb", vision::Detector::Orb},
									      {"surf", vision::Detector::Surf}}));
		o.push_back(number(
			"features", "max_features", "ORB keypoints kept per frame",
			[](DaemonConfig &c) -> int & { return c.motion.features.max_features; }, 16, 20000));
		o.push_back(number(
			"features", "grid_cols", "bucketing grid columns",
			[](DaemonConfig &c) -> int & { return c.motion.features.grid_cols; }, 1, 64));
		o.push_back(number(
			"features", "grid_rows", "bucketing grid rows",
			[](DaemonConfig &c) -> int & { return c.motion.features.grid_rows; }, 1, 64));
		o.push_back(number(
			"features", "orb_levels", "ORB pyramid levels",
			[](DaemonConfig &c) -> int & { return c.motion.features.orb_levels; }, 1, 12));
		o.push_back(number(
			"features", "orb_scale", "ORB pyramid scale step",
			[](DaemonConfig &c) -> float & { return c.motion.features.orb_scale; }, 1.05, 2.0));
		o.push_back(number(
			"features", "orb_fast_threshold", "FAST corner threshold",
			[](DaemonConfig &c) -> int & { return c.motion.features.orb_fast_threshold; }, 1, 100));
		o.push_back(number(
			"features", "candidates_per_feature",
			"corners detected per point kept, before the grid shares the budget (more reach weakly "
			"textured cells)",
			[](DaemonConfig &c) -> int & { return c.motion.features.candidates_per_feature; }, 1, 50));
		o.push_back(enumeration(
			"features", "candidate_selection",
			"per_cell (each grid cell ranks its own FAST corners: plain regions keep points) | whole_image "
			"(OpenCV's ORB detector: the image's strongest, then the grid)",
			[](DaemonConfig &c) -> vision::CandidateSelection & {
				return c.motion.features.candidate_selection;
			},
			std::vector<std::pair<std::string, vision::CandidateSelection>>{
				{"per_cell", vision::CandidateSelection::PerCell},
				{"whole_image", vision::CandidateSelection::WholeImage}}));
		o.push_back(number(
			"features", "min_corner_quality",
			"per_cell: candidates under this fraction of the frame's strongest Harris response (its 99th "
			"percentile) are dropped; 0 keeps all",
			[](DaemonConfig &c) -> float & { return c.motion.features.min_corner_quality; }, 0.0, 1.0));
		o.push_back(number(
			"features", "surf_hessian_threshold", "SURF: minimum det(H) of a keypoint",
			[](DaemonConfig &c) -> double & { return c.motion.features.surf.hessian_threshold; }, 0, 1e6));
		o.push_back(number(
			"features", "surf_octaves", "SURF: octaves",
			[](DaemonConfig &c) -> int & { return c.motion.features.surf.octaves; }, 1, 6));
		o.push_back(number(
			"features", "surf_initial_step", "SURF: sampling step of the first octave",
			[](DaemonConfig &c) -> int & { return c.motion.features.surf.initial_step; }, 1, 4));
		o.push_back(boolean("features", "surf_extended", "SURF: 128-d descriptors instead of 64-d",
				    [](DaemonConfig &c) -> bool & { return c.motion.features.surf.extended; }));
		o.push_back(boolean("features", "surf_upright", "SURF: no orientation (U-SURF), faster",
				    [](DaemonConfig &c) -> bool & { return c.motion.features.surf.upright; }));
		// [matching]
		o.push_back(number(
			"matching", "ratio", "Lowe ratio test; 1 = off",
			[](DaemonConfig &c) -> float & { return c.motion.matching.ratio; }, 0.1, 1.0));
		o.push_back(boolean("matching", "cross_check", "keep mutual best matches only",
				    [](DaemonConfig &c) -> bool & { return c.motion.matching.cross_check; }));
		o.push_back(number(
			"matching", "max_distance", "largest Hamming distance accepted",
			[](DaemonConfig &c) -> int & { return c.motion.matching.max_distance; }, 1, 256));
		o.push_back(number(
			"matching", "search_radius_px",
			"guided matching: candidates within this of the predicted position; 0 = brute force",
			[](DaemonConfig &c) -> float & { return c.motion.matching.search_radius_px; }, 0, 10000));
		o.push_back(boolean("matching", "subpixel", "refine matches to a fraction of a pixel (Lucas-Kanade)",
				    [](DaemonConfig &c) -> bool & { return c.motion.matching.subpixel; }));
		o.push_back(boolean(
			"matching", "rescue",
			"unmatched keypoints followed by Lucas-Kanade and joined to an unmatched one where they land",
			[](DaemonConfig &c) -> bool & { return c.motion.matching.rescue; }));
		o.push_back(number(
			"matching", "rescue_radius_px", "rescue: largest distance from where Lucas-Kanade lands",
			[](DaemonConfig &c) -> float & { return c.motion.matching.rescue_radius_px; }, 0.1, 10));
		o.push_back(number(
			"matching", "rescue_back_px", "rescue: largest round-trip error of Lucas-Kanade",
			[](DaemonConfig &c) -> float & { return c.motion.matching.rescue_back_px; }, 0.01, 10));
		o.push_back(number(
			"matching", "rescue_reach_px",
			"rescue: followed only with an unmatched keypoint this near its prediction",
			[](DaemonConfig &c) -> float & { return c.motion.matching.rescue_reach_px; }, 0.1, 100));
		o.push_back(number(
			"matching", "rescue_max_distance",
			"rescue: largest Hamming distance between the two descriptors; 256 = not looked at",
			[](DaemonConfig &c) -> int & { return c.motion.matching.rescue_max_distance; }, 1, 256));
		o.push_back(boolean("matching", "follow_lost",
				    "a followed corner the detector loses is kept where Lucas-Kanade lands, so its "
				    "track goes on",
				    [](DaemonConfig &c) -> bool & { return c.motion.matching.follow_lost; }));
		o.push_back(number(
			"matching", "follow_lost_clear_px",
			"follow_lost: not where a matched keypoint lies this close (that corner is followed already)",
			[](DaemonConfig &c) -> float & { return c.motion.matching.follow_lost_clear_px; }, 0, 50));
		o.push_back(number(
			"matching", "follow_max_error_ratio",
			"a followed point whose window differs from the corner's by more than this many times the "
			"frame's median difference is refused; 0 = no check",
			[](DaemonConfig &c) -> float & { return c.motion.matching.follow_max_error_ratio; }, 0, 1000));
		// [classifier]
		o.push_back(number(
			"classifier", "ransac_threshold_px", "RANSAC inlier distance, pixels",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.ransac_threshold_px; }, 0.1, 50));
		o.push_back(number(
			"classifier", "reprojection_sigma_px", "feature position noise for eq. 1, pixels",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.reprojection_sigma_px; }, 0.05,
			20));
		o.push_back(number(
			"classifier", "reprojection_chi2",
			"gate on eq. 1 over sigma^2 (chi-square, 2 dof: 9.21 is 99%)",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.reprojection_chi2; }, 0.1, 1000));
		o.push_back(number(
			"classifier", "static_theta", "eq. 5 static window, u: du^2 < theta * Umax",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.static_theta; }, 0, 1));
		o.push_back(number(
			"classifier", "static_eta", "eq. 5 static window, v: dv^2 < eta * Vmax",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.static_eta; }, 0, 1));
		o.push_back(number(
			"classifier", "dynamic_theta", "eq. 5 dynamic window, u",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.dynamic_theta; }, 0, 1));
		o.push_back(number(
			"classifier", "dynamic_eta", "eq. 5 dynamic window, v",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.dynamic_eta; }, 0, 1));
		o.push_back(number(
			"classifier", "area_floor_px", "smallest area window, pixels",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.area_floor_px; }, 0, 100));
		o.push_back(number(
			"classifier", "dynamic_max_motion_px", "largest plausible mover motion per frame",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.dynamic_max_motion_px; }, 1,
			10000));
		o.push_back(number(
			"classifier", "alpha", "eq. 3 weight of R (alpha + beta + gamma = 1)",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.alpha; }, 0, 1));
		o.push_back(number(
			"classifier", "beta", "eq. 3 weight of G",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.beta; }, 0, 1));
		o.push_back(number(
			"classifier", "gamma", "eq. 3 weight of B",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.gamma; }, 0, 1));
		o.push_back(number(
			"classifier", "texture_threshold", "T of eqs. 2 and 7, 8-bit units",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.texture_threshold; }, 0, 255));
		o.push_back(number(
			"classifier", "texture_tolerance_px", "eq. 3 compares the best match within this many px",
			[](DaemonConfig &c) -> int & { return c.motion.classifier.texture_tolerance_px; }, 0, 5));
		o.push_back(number(
			"classifier", "colour_radius", "colours are means of (2r+1)^2 pixels (eqs. 3, 6)",
			[](DaemonConfig &c) -> int & { return c.motion.classifier.colour_radius; }, 0, 10));
		o.push_back(number(
			"classifier", "min_matches", "fewer matches: no homography, all uncertain",
			[](DaemonConfig &c) -> int & { return c.motion.classifier.min_matches; }, 4, 100000));
		o.push_back(enumeration(
			"classifier", "label_method",
			"with depth: combined | geometric (seed 001) | seed000 (homography only)",
			[](DaemonConfig &c) -> vision::LabelMethod & { return c.motion.label_method; },
			std::vector<std::pair<std::string, vision::LabelMethod>>{
				{"combined", vision::LabelMethod::Combined},
				{"geometric", vision::LabelMethod::Geometric},
				{"seed000", vision::LabelMethod::Seed000}}));
		// [stereo]: sparse stereo on rectified pairs (core/vision/stereo.hpp)
		o.push_back(boolean("stereo", "enabled", "match the right eye for depth when the source is calibrated",
				    [](DaemonConfig &c) -> bool & { return c.motion.stereo.enabled; }));
		o.push_back(number(
			"stereo", "max_row_diff_px",
			"epipolar constraint: rows may differ this much (per pyramid level)",
			[](DaemonConfig &c) -> double & { return c.motion.stereo.max_row_diff_px; }, 0, 16));
		o.push_back(number(
			"stereo", "min_disparity_px", "smallest disparity measured (farthest depth f b / d)",
			[](DaemonConfig &c) -> double & { return c.motion.stereo.min_disparity_px; }, 0.1, 1000));
		o.push_back(number(
			"stereo", "max_disparity_px", "largest disparity searched (nearest depth)",
			[](DaemonConfig &c) -> double & { return c.motion.stereo.max_disparity_px; }, 1, 4096));
		o.push_back(number(
			"stereo", "max_distance", "descriptor distance limit (Hamming bits for ORB)",
			[](DaemonConfig &c) -> int & { return c.motion.stereo.max_distance; }, 1, 512));
		o.push_back(number(
			"stereo", "ratio", "Lowe's ratio among the candidates in the epipolar band",
			[](DaemonConfig &c) -> float & { return c.motion.stereo.ratio; }, 0.1, 1));
		o.push_back(number(
			"stereo", "window_radius_px", "sub-pixel refinement window half-size",
			[](DaemonConfig &c) -> int & { return c.motion.stereo.window_radius_px; }, 1, 15));
		o.push_back(number(
			"stereo", "edge_split_px",
			"a match whose window's halves (left / right, top / bottom) refine to disparities more than "
			"this apart straddles a depth edge (0: no test)",
			[](DaemonConfig &c) -> double & { return c.motion.stereo.edge_split_px; }, 0, 100));
		o.push_back(boolean("stereo", "drop_edge_depth",
				    "no depth at all for a match across a depth edge (better labels and depth, fewer "
				    "groups); false: kept, but not for a group's velocity",
				    [](DaemonConfig &c) -> bool & { return c.motion.stereo.drop_edge_depth; }));
		o.push_back(
			boolean("stereo", "row_search",
				"look for unmatched left keypoints along their row of the right image (correlation)",
				[](DaemonConfig &c) -> bool & { return c.motion.stereo.row_search; }));
		o.push_back(boolean(
			"stereo", "right_features",
			"match the right eye's own features (seed 002) every frame; false: the row search, faster",
			[](DaemonConfig &c) -> bool & { return c.motion.stereo.right_features; }));
		o.push_back(number(
			"stereo", "health_every_frames",
			"right_features off: match the right eye's features every this many frames for the rig's "
			"health (0 = never)",
			[](DaemonConfig &c) -> int & { return c.motion.stereo.health_every_frames; }, 0, 100000));
		o.push_back(number(
			"stereo", "row_search_min_ncc", "correlation a row-search match needs",
			[](DaemonConfig &c) -> double & { return c.motion.stereo.row_search_min_ncc; }, 0, 1));
		o.push_back(number(
			"stereo", "row_search_uniqueness",
			"row search: (1 - best) <= this * (1 - best more than 2 px away)",
			[](DaemonConfig &c) -> double & { return c.motion.stereo.row_search_uniqueness; }, 0, 1));
		o.push_back(number(
			"stereo", "disparity_sigma_px", "disparity noise after refinement (depth uncertainty)",
			[](DaemonConfig &c) -> double & { return c.motion.stereo.disparity_sigma_px; }, 0.01, 10));
		// [ego]: the camera's motion from stereo (core/vision/ego.hpp)
		o.push_back(boolean("ego", "enabled", "estimate the metric pose when the source has depth",
				    [](DaemonConfig &c) -> bool & { return c.motion.ego.enabled; }));
		o.push_back(boolean("ego", "anchor_refine",
				    "refine the chained pose against the anchored static points in view",
				    [](DaemonConfig &c) -> bool & { return c.motion.ego.anchor_refine; }));
		o.push_back(number(
			"ego", "anchor_refine_min_points", "anchored points the refinement needs",
			[](DaemonConfig &c) -> int & { return c.motion.ego.anchor_refine_min_points; }, 3, 100000));
		o.push_back(number(
			"ego", "anchor_refine_gain", "share of the refinement's correction applied per frame",
			[](DaemonConfig &c) -> double & { return c.motion.ego.anchor_refine_gain; }, 0.01, 1));
		o.push_back(number(
			"ego", "ransac_threshold_px", "PnP RANSAC inlier distance",
			[](DaemonConfig &c) -> double & { return c.motion.ego.ransac_threshold_px; }, 0.1, 50));
		o.push_back(number(
			"ego", "ransac_threshold_sigmas",
			"fit the pose at this many times its measured noise (0: at ransac_threshold_px only)",
			[](DaemonConfig &c) -> double & { return c.motion.ego.ransac_threshold_sigmas; }, 0, 100));
		o.push_back(number(
			"ego", "min_ransac_threshold_px", "the inlier distance at the measured noise at least, pixels",
			[](DaemonConfig &c) -> double & { return c.motion.ego.min_ransac_threshold_px; }, 0.05, 50));
		o.push_back(number(
			"ego", "ransac_iterations", "P3P samples drawn per frame (up to four hypotheses each)",
			[](DaemonConfig &c) -> int & { return c.motion.ego.ransac_iterations; }, 1, 100000));
		o.push_back(number(
			"ego", "ransac_confidence",
			"stop sampling once an all-inlier sample was drawn with this probability (0: draw them all)",
			[](DaemonConfig &c) -> double & { return c.motion.ego.ransac_confidence; }, 0, 0.999999));
		o.push_back(boolean(
			"ego", "ransac_spread_score",
			"RANSAC prefers the pose whose inliers spread over more of the image, then more inliers",
			[](DaemonConfig &c) -> bool & { return c.motion.ego.ransac_spread_score; }));
		o.push_back(number(
			"ego", "max_depth_m", "farther points do not vote for the pose",
			[](DaemonConfig &c) -> double & { return c.motion.ego.max_depth_m; }, 0.1, 100000));
		o.push_back(number(
			"ego", "max_acceleration_mps2", "motion prior: the camera's largest acceleration; 0 = no prior",
			[](DaemonConfig &c) -> double & { return c.motion.ego.max_acceleration_mps2; }, 0, 10000));
		o.push_back(number(
			"ego", "max_angular_acceleration_radps2", "motion prior: the largest angular acceleration",
			[](DaemonConfig &c) -> double & { return c.motion.ego.max_angular_acceleration_radps2; }, 0,
			10000));
		o.push_back(number(
			"ego", "min_inliers", "fewer: the pose is not trusted (ego.valid false)",
			[](DaemonConfig &c) -> int & { return c.motion.ego.min_inliers; }, 6, 100000));
		o.push_back(number(
			"ego", "pixel_sigma_px", "feature position noise of the geometric test (measured_noise off)",
			[](DaemonConfig &c) -> double & { return c.motion.ego.pixel_sigma_px; }, 0.01, 20));
		o.push_back(number(
			"ego", "chi2_quantile", "the geometric test's confidence (false alarms: 1 - this)",
			[](DaemonConfig &c) -> double & { return c.motion.ego.chi2_quantile; }, 0.5, 0.999999));
		o.push_back(number(
			"ego", "confirm_frames", "frames in a row a point must fail the test to be dynamic",
			[](DaemonConfig &c) -> int & { return c.motion.ego.confirm_frames; }, 1, 100));
		o.push_back(number(
			"ego", "confirm_motion_change",
			"confirmation: the own motion may change by this fraction between the two failures; 0 = any",
			[](DaemonConfig &c) -> double & { return c.motion.ego.confirm_motion_change; }, 0, 10));
		o.push_back(boolean("ego", "measured_noise", "take the test's pixel noise from each frame's pose fit",
				    [](DaemonConfig &c) -> bool & { return c.motion.ego.measured_noise; }));
		o.push_back(number(
			"ego", "min_pixel_sigma_px", "floor of the measured pixel noise, per axis",
			[](DaemonConfig &c) -> double & { return c.motion.ego.min_pixel_sigma_px; }, 0.01, 20));
		o.push_back(number(
			"ego", "min_disparity_sigma_px", "floor of the measured disparity noise",
			[](DaemonConfig &c) -> double & { return c.motion.ego.min_disparity_sigma_px; }, 0.001, 20));
		o.push_back(number(
			"ego", "min_parallax_px",
			"combined: points the translation moves less than this keep seed 000's label",
			[](DaemonConfig &c) -> double & { return c.motion.ego.min_parallax_px; }, 0, 1000));
		o.push_back(number(
			"ego", "anchor_min_frames", "anchored depth test after this many frames of a track; 0 = off",
			[](DaemonConfig &c) -> int & { return c.motion.ego.anchor_min_frames; }, 0, 100000));
		o.push_back(number(
			"ego", "anchor_max_speed_mps",
			"anchored test: a track whose depth leaps faster than this between frames is anchored again; 0 "
			"= off",
			[](DaemonConfig &c) -> double & { return c.motion.ego.anchor_max_speed_mps; }, 0, 1000));
		o.push_back(number(
			"ego", "anchor_spread_px",
			"young tracks this close (pixels) to points the anchored test found, at the same depth, are "
			"dynamic too; 0 = off",
			[](DaemonConfig &c) -> double & { return c.motion.ego.anchor_spread_px; }, 0, 10000));
		o.push_back(number(
			"ego", "anchor_spread_depth", "anchored spread: same depth within this fraction of the nearer",
			[](DaemonConfig &c) -> double & { return c.motion.ego.anchor_spread_depth; }, 0, 10));
		o.push_back(number(
			"ego", "anchor_spread_min", "anchored spread: found points a young track needs beside it",
			[](DaemonConfig &c) -> int & { return c.motion.ego.anchor_spread_min; }, 1, 100000));
		o.push_back(number(
			"ego", "anchor_pool_samples",
			"pooled drift test: a track's signed depth drift counts once its anchor holds this many "
			"depths; 0 = off",
			[](DaemonConfig &c) -> int & { return c.motion.ego.anchor_pool_samples; }, 0, 100000));
		o.push_back(number(
			"ego", "anchor_pool_px", "pooled drift test: a point's neighbours lie this close (pixels)",
			[](DaemonConfig &c) -> double & { return c.motion.ego.anchor_pool_px; }, 1, 10000));
		o.push_back(number(
			"ego", "anchor_pool_min",
			"pooled drift test: points with a drift within anchor_pool_px and the spread's depth a point "
			"needs",
			[](DaemonConfig &c) -> int & { return c.motion.ego.anchor_pool_min; }, 1, 100000));
		o.push_back(number(
			"ego", "anchor_pool_sigmas",
			"pooled drift test: the neighbourhood's summed drift over sqrt(count) must exceed this",
			[](DaemonConfig &c) -> double & { return c.motion.ego.anchor_pool_sigmas; }, 0.1, 1000));
		o.push_back(number(
			"ego", "anchor_pool_hold_sigmas",
			"pooled drift test: the gate for a track it found in the frames before (anchor_pool_sigmas to "
			"turn off)",
			[](DaemonConfig &c) -> double & { return c.motion.ego.anchor_pool_hold_sigmas; }, 0.1, 1000));
		o.push_back(boolean("ego", "depth_check", "test the depth measured at frame n (seed 001 eq. 4)",
				    [](DaemonConfig &c) -> bool & { return c.motion.ego.depth_check; }));
		o.push_back(boolean("ego", "along_line",
				    "test the position along the epipolar line too (beyond seed 001)",
				    [](DaemonConfig &c) -> bool & { return c.motion.ego.along_line; }));
		// [memory]: beyond the seed (core/vision/temporal.hpp)
		o.push_back(number(
			"memory", "window_s", "time constant of each point's remembered own motion; 0 = seed only",
			[](DaemonConfig &c) -> double & { return c.motion.temporal.window_s; }, 0, 60));
		o.push_back(number(
			"memory", "chi2", "gate on the remembered own motion (chi-square, 2 dof)",
			[](DaemonConfig &c) -> double & { return c.motion.temporal.chi2; }, 0.1, 1000));
		o.push_back(number(
			"memory", "jump_chi2",
			"a frame's motion this far from its track's mean breaks the track (2 dof)",
			[](DaemonConfig &c) -> double & { return c.motion.temporal.jump_chi2; }, 0.1, 1000));
		o.push_back(number(
			"memory", "min_age", "frames a point is followed before its memory may label it",
			[](DaemonConfig &c) -> int & { return c.motion.temporal.min_age; }, 1, 10000));

		// [groups]: moving-target groups (core/vision/groups.hpp)
		o.push_back(boolean("groups", "enabled", "find moving-target groups (seed 002's flow clustering)",
				    [](DaemonConfig &c) -> bool & { return c.motion.groups.enabled; }));
		o.push_back(enumeration(
			"groups", "members",
			"points clustered: auto (labels with a metric pose, else flow) | flow (seed 002's mean-flow "
			"split) | labels (those labelled dynamic)",
			[](DaemonConfig &c) -> vision::GroupMembers & { return c.motion.groups.members; },
			std::vector<std::pair<std::string, vision::GroupMembers>>{
				{"auto", vision::GroupMembers::Auto},
				{"flow", vision::GroupMembers::Flow},
				{"labels", vision::GroupMembers::Labels}}));
		o.push_back(enumeration(
			"groups", "flow",
			"motion the groups come from: sparse (the feature points' matches) | lk (seed 002's pyramidal "
			"LK on a grid) | dis (DIS dense flow, averaged per grid cell)",
			[](DaemonConfig &c) -> vision::GroupFlow & { return c.motion.dense.method; },
			std::vector<std::pair<std::string, vision::GroupFlow>>{{"sparse", vision::GroupFlow::Sparse},
									       {"lk", vision::GroupFlow::PyrLk},
									       {"dis", vision::GroupFlow::Dis}}));
		o.push_back(number(
			"groups", "flow_scale", "lk / dis: the flow runs on the left image scaled by this",
			[](DaemonConfig &c) -> double & { return c.motion.dense.scale; }, 0.05, 1));
		o.push_back(number(
			"groups", "cell_px", "lk / dis: grid cell side (full-resolution pixels); a cell is one sample",
			[](DaemonConfig &c) -> int & { return c.motion.dense.step_px; }, 2, 256));
		o.push_back(number(
			"groups", "lk_window", "lk: window side (seed 002: 7)",
			[](DaemonConfig &c) -> int & { return c.motion.dense.lk_window; }, 3, 63));
		o.push_back(number(
			"groups", "lk_levels", "lk: pyramid levels above the original (seed 002: 3)",
			[](DaemonConfig &c) -> int & { return c.motion.dense.lk_levels; }, 0, 8));
		o.push_back(number(
			"groups", "lk_min_eigen",
			"lk: weaker gradients (minimum eigenvalue) carry no motion (seed 002: 0.001)",
			[](DaemonConfig &c) -> double & { return c.motion.dense.lk_min_eigen; }, 0, 1));
		o.push_back(number(
			"groups", "aperture_ratio",
			"lk / dis: a cell whose gradients run one way (smaller/larger eigenvalue under this) is on an "
			"edge; a group mostly of cells that moved only along their edges is dropped (0: off)",
			[](DaemonConfig &c) -> double & { return c.motion.dense.aperture_ratio; }, 0, 1));
		o.push_back(number(
			"groups", "max_round_trip_px",
			"lk / dis: a cell's flow followed back must land this close to its start (0: no check)",
			[](DaemonConfig &c) -> double & { return c.motion.dense.max_round_trip_px; }, 0, 1000));
		o.push_back(number(
			"groups", "min_strong_neighbours",
			"lk / dis: strong cells a strong cell needs among its 8 neighbours (0: none)",
			[](DaemonConfig &c) -> int & { return c.motion.dense.min_strong_neighbours; }, 0, 8));
		o.push_back(number(
			"groups", "min_cells", "lk / dis: grid cells a group needs at least",
			[](DaemonConfig &c) -> int & { return c.motion.dense.min_cells; }, 1, 100000));
		o.push_back(number(
			"groups", "min_box_fill",
			"lk / dis: fraction of a group's box its cells must cover (scattered noise is not a mover)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.min_box_fill; }, 0, 1));
		o.push_back(number(
			"groups", "depth_radius_cells",
			"lk / dis: a cell's depth is the median of the stereo points within this many cells",
			[](DaemonConfig &c) -> int & { return c.motion.dense.depth_radius_cells; }, 0, 32));
		o.push_back(boolean("groups", "label_cells",
				    "lk / dis: a point on a cell a group holds is labelled dynamic with it",
				    [](DaemonConfig &c) -> bool & { return c.motion.dense.label_cells; }));
		o.push_back(number(
			"groups", "min_flow_px",
			"shortest residual flow (pixels per frame) that counts as strong motion",
			[](DaemonConfig &c) -> double & { return c.motion.groups.min_flow_px; }, 0, 1000));
		o.push_back(number(
			"groups", "noise_sigmas",
			"flow members: the floor min_flow_px falls, to min_flow_floor_px at the least, to this "
			"many times the frame's residual noise where that is less (0: min_flow_px always)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.noise_sigmas; }, 0, 1000));
		o.push_back(number(
			"groups", "min_flow_floor_px",
			"flow members: the lowest the noise can take the floor to, pixels per frame",
			[](DaemonConfig &c) -> double & { return c.motion.groups.min_flow_floor_px; }, 0, 1000));
		o.push_back(number(
			"groups", "position_scale_px", "sample normalisation: image distance still in one group",
			[](DaemonConfig &c) -> double & { return c.motion.groups.position_scale_px; }, 1, 10000));
		o.push_back(number(
			"groups", "flow_scale_px",
			"sample normalisation: flow difference (pixels per frame) still in one group",
			[](DaemonConfig &c) -> double & { return c.motion.groups.flow_scale_px; }, 0.01, 1000));
		o.push_back(number(
			"groups", "disparity_scale_px", "sample normalisation: disparity difference still in one group",
			[](DaemonConfig &c) -> double & { return c.motion.groups.disparity_scale_px; }, 0.01, 1000));
		o.push_back(number(
			"groups", "octave_scale", "sample normalisation: pyramid levels still in one group",
			[](DaemonConfig &c) -> double & { return c.motion.groups.octave_scale; }, 0.01, 100));
		o.push_back(number(
			"groups", "max_points", "strong points clustered per frame at most (an even subsample beyond)",
			[](DaemonConfig &c) -> int & { return c.motion.groups.max_points; }, 1, 100000));
		o.push_back(number(
			"groups", "min_points", "points a cluster needs to be a group",
			[](DaemonConfig &c) -> int & { return c.motion.groups.min_points; }, 1, 100000));
		o.push_back(number(
			"groups", "merge_gap_px",
			"clusters whose boxes come this close (pixels) and move alike are merged (negative: never)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.merge_gap_px; }, -1, 10000));
		o.push_back(number(
			"groups", "split_gap_cells",
			"lk / dis: a cluster is cut into connected regions of cells at most this many empty cells "
			"apart "
			"(negative: not cut)",
			[](DaemonConfig &c) -> int & { return c.motion.groups.split_gap_cells; }, -1, 1000));
		o.push_back(number(
			"groups", "box_margin_px",
			"sparse: a group's box is its feature points' extent grown by this many pixels (the body "
			"reaches beyond its corners)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.box_margin_px; }, 0, 10000));
		o.push_back(number(
			"groups", "split_gap_px",
			"sparse, feature points without depth (monocular): a cluster is cut into connected parts of "
			"points at most this many pixels apart (0: not cut)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.split_gap_px; }, 0, 100000));
		o.push_back(number(
			"groups", "split_same_depth",
			"regions of a cut cluster (lk / dis), and clusters that move alike no farther apart than the "
			"larger one's longer side (lk / dis) or merge_reach_m (sparse), whose median depths agree "
			"within this share of the nearer are one group (0: depth not looked at)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.split_same_depth; }, 0, 10));
		o.push_back(number(
			"groups", "merge_reach_m",
			"sparse flow with depth: clusters that move alike at one depth (split_same_depth) whose boxes "
			"are at most this many metres apart are one group (0: not joined)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.merge_reach_m; }, 0, 1000));
		o.push_back(number(
			"groups", "merge_looming",
			"clusters at one depth, one above the other, also move alike when their residuals differ as a "
			"mover's coming at the camera spreads its pieces apart, by at most this share of their gap a "
			"frame (0: not looked at)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.merge_looming; }, 0, 1));
		o.push_back(
			boolean("groups", "regroup_unplaced",
				"the points the clustering placed in no group are clustered once more among themselves",
				[](DaemonConfig &c) -> bool & { return c.motion.groups.regroup_unplaced; }));
		o.push_back(number(
			"groups", "regroup_preference_scale",
			"the second round's Affinity Propagation preference = this x the first round's (1: "
			"the same; smaller: more clusters among the leftovers)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.regroup_preference_scale; }, 0.01,
			100));
		o.push_back(boolean(
			"groups", "keep_labels_in_box",
			"a point published dynamic in the frame before stays dynamic while inside a group's box",
			[](DaemonConfig &c) -> bool & { return c.motion.groups.keep_labels_in_box; }));
		o.push_back(number(
			"groups", "new_in_box_frames",
			"labels: a point whose track is at most this many frames old, within the members' extent "
			"of a group whose box shows new corners twice as often as the static scene (at its "
			"depth), is dynamic; 0: off",
			[](DaemonConfig &c) -> int & { return c.motion.groups.new_in_box_frames; }, 0, 1000));
		o.push_back(number(
			"groups", "new_below_box_share",
			"labels: new_in_box_frames also takes the new points under such a group's members, down "
			"to this share of their height (a walker's standing leg; an upright camera); 0: none",
			[](DaemonConfig &c) -> double & { return c.motion.groups.new_below_box_share; }, 0, 10));
		o.push_back(
			boolean("groups", "follow_unmatched",
				"sparse flow: the previous frame's unmatched keypoints are followed by Lucas-Kanade "
				"and clustered beside the matched ones (seed 002's split only)",
				[](DaemonConfig &c) -> bool & { return c.motion.groups.follow_unmatched; }));
		o.push_back(number(
			"groups", "neighbours", "Affinity Propagation: messages to this many nearest samples",
			[](DaemonConfig &c) -> int & { return c.motion.groups.affinity.neighbours; }, 1, 10000));
		o.push_back(boolean(
			"groups", "symmetric_neighbours",
			"Affinity Propagation: a pair is linked both ways when either is among the other's nearest",
			[](DaemonConfig &c) -> bool & { return c.motion.groups.affinity.symmetric; }));
		o.push_back(number(
			"groups", "damping", "Affinity Propagation: damping lambda",
			[](DaemonConfig &c) -> double & { return c.motion.groups.affinity.damping; }, 0.5, 0.99));
		o.push_back(number(
			"groups", "max_iterations", "Affinity Propagation: iteration cap",
			[](DaemonConfig &c) -> int & { return c.motion.groups.affinity.max_iterations; }, 1, 100000));
		o.push_back(number(
			"groups", "preference_scale",
			"Affinity Propagation: preference = this x the minimum similarity (seed 002: 1)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.affinity.preference_scale; }, 0.001,
			1000));
		o.push_back(number(
			"groups", "association_px",
			"tracks: largest distance from a group's predicted centre to a new cluster",
			[](DaemonConfig &c) -> double & { return c.motion.groups.association_px; }, 1, 10000));
		o.push_back(number(
			"groups", "max_missed_frames", "tracks: frames a group is remembered unseen",
			[](DaemonConfig &c) -> int & { return c.motion.groups.max_missed_frames; }, 0, 1000));
		o.push_back(number(
			"groups", "min_age_frames", "tracks: frames a group must be seen before it is published",
			[](DaemonConfig &c) -> int & { return c.motion.groups.min_age_frames; }, 1, 1000));
		o.push_back(number(
			"groups", "coast_frames",
			"tracks: a published group not found is published on (moved by its velocities, missed_frames > "
			"0) "
			"for this many frames, at most max_missed_frames and no longer than it had been published; 0: "
			"never",
			[](DaemonConfig &c) -> int & { return c.motion.groups.coast_frames; }, 0, 1000));
		o.push_back(number(
			"groups", "edge_coast_frames",
			"tracks: a published group leaving the view sideways through the edge band (fast enough to "
			"cross it in this many frames) is remembered and published on for up to this many frames while "
			"half its predicted box is in the image (no longer than it had been published); 0: as any "
			"group",
			[](DaemonConfig &c) -> int & { return c.motion.groups.edge_coast_frames; }, 0, 1000));
		o.push_back(number(
			"groups", "edge_band_px",
			"tracks: the band along the image's left and right edges where feature points give out (ORB "
			"keeps no corner within 31 px), pixels",
			[](DaemonConfig &c) -> double & { return c.motion.groups.edge_band_px; }, 0, 1000));
		o.push_back(number(
			"groups", "occlusion_frames",
			"tracks: a published group not found whose predicted box lies at least half behind a nearer "
			"group found in the frame is remembered (coasted only coast_frames) this many frames; 0: as "
			"any group",
			[](DaemonConfig &c) -> int & { return c.motion.groups.occlusion_frames; }, 0, 1000));
		o.push_back(number(
			"groups", "smoothing",
			"tracks: weight of the new measurement in the metric velocity averages (after a running "
			"mean over the first 1 / smoothing frames)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.smoothing; }, 0.01, 1));
		o.push_back(number(
			"groups", "image_smoothing", "tracks: the same for the image velocity that predicts the box",
			[](DaemonConfig &c) -> double & { return c.motion.groups.image_smoothing; }, 0.01, 1));
		o.push_back(number(
			"groups", "velocity_window_s",
			"tracks: the metric velocities' component along the line of sight from a line fitted to the "
			"track's world positions over this many seconds (the depth's frame-to-frame noise averages "
			"out); 0: the averages alone",
			[](DaemonConfig &c) -> double & { return c.motion.groups.velocity_window_s; }, 0, 60));
		o.push_back(boolean(
			"groups", "anchored_velocity",
			"tracks: until that window is half full, also take the velocity along the line of sight "
			"from the members' anchors (where their tracks were a third of a second or more ago)",
			[](DaemonConfig &c) -> bool & { return c.motion.groups.anchored_velocity; }));
		o.push_back(boolean("groups", "label_points", "label points inside a group moving with it dynamic",
				    [](DaemonConfig &c) -> bool & { return c.motion.groups.label_points; }));
		o.push_back(number(
			"groups", "label_tolerance_px",
			"labels: residual difference to the group's still counted as moving with it",
			[](DaemonConfig &c) -> double & { return c.motion.groups.label_tolerance_px; }, 0, 1000));
		o.push_back(number(
			"groups", "member_tolerance_px",
			"lk / dis: residual difference to a cluster's for a grid cell member, or between clusters that "
			"move alike",
			[](DaemonConfig &c) -> double & { return c.motion.groups.member_tolerance_px; }, 0, 1000));
		o.push_back(number(
			"groups", "point_tolerance_px",
			"sparse: the same for feature points (their positions are quantised to their pyramid level)",
			[](DaemonConfig &c) -> double & { return c.motion.groups.point_tolerance_px; }, 0, 1000));

		// [prior]: seed 001's person prior (core/vision/person_prior.hpp)
		o.push_back(boolean("prior", "enabled",
				    "seed 001's prior: people (prior.detector) leave the motion fits",
				    [](DaemonConfig &c) -> bool & { return c.motion.prior.enabled; }));
		o.push_back(number(
			"prior", "every_n_frames", "run the detector on every n-th frame, carry its boxes between",
			[](DaemonConfig &c) -> int & { return c.motion.prior.every_n_frames; }, 1, 1000));
		o.push_back(number(
			"prior", "min_score", "SVM margin a detection needs (higher: fewer, surer people)",
			[](DaemonConfig &c) -> double & { return c.motion.prior.min_score; }, -10, 100));
		o.push_back(number(
			"prior", "upscale", "detect on the image scaled by this (people under ~128 px tall need > 1)",
			[](DaemonConfig &c) -> double & { return c.motion.prior.upscale; }, 0.25, 4));
		o.push_back(number(
			"prior", "margin", "grow each box by this fraction of its size on every side",
			[](DaemonConfig &c) -> double & { return c.motion.prior.margin; }, 0, 1));
		o.push_back(number(
			"prior", "max_age_frames", "forget a carried box after this many frames without a detection",
			[](DaemonConfig &c) -> int & { return c.motion.prior.max_age_frames; }, 1, 1000));
		o.push_back(enumeration(
			"prior", "points",
			"points in a person box: weighted (memory gate memory_chi2) | judged | dynamic (seed 001)",
			[](DaemonConfig &c) -> vision::PriorLabelRule & { return c.motion.prior.rule; },
			std::vector<std::pair<std::string, vision::PriorLabelRule>>{
				{"weighted", vision::PriorLabelRule::Weighted},
				{"judged", vision::PriorLabelRule::Judged},
				{"dynamic", vision::PriorLabelRule::Dynamic}}));
		o.push_back(number(
			"prior", "memory_chi2", "weighted: the motion memory's gate for points in a person box",
			[](DaemonConfig &c) -> double & { return c.motion.prior.memory_chi2; }, 0.01, 1000));
		o.push_back(enumeration(
			"prior", "detector", "hog (OpenCV's people detector, no weights) | onnx (prior.model)",
			[](DaemonConfig &c) -> vision::PriorDetector & { return c.motion.prior.detector; },
			std::vector<std::pair<std::string, vision::PriorDetector>>{
				{"hog", vision::PriorDetector::Hog}, {"onnx", vision::PriorDetector::Onnx}}));
		o.push_back(text("prior", "model", "onnx: the model file (read at start; refused if it does not fit)",
				 [](DaemonConfig &c) -> std::string & { return c.motion.prior.model_path; }));
		o.push_back(enumeration(
			"prior", "model_layout",
			"onnx output: yolov8 (1x(4+C)xN) | yolov5 (1xNx(5+C)) | segmentation (1xCxhxw scores)",
			[](DaemonConfig &c) -> vision::ModelLayout & { return c.motion.prior.model_spec.layout; },
			std::vector<std::pair<std::string, vision::ModelLayout>>{
				{"yolov8", vision::ModelLayout::Yolov8},
				{"yolov5", vision::ModelLayout::Yolov5},
				{"segmentation", vision::ModelLayout::Segmentation}}));
		o.push_back(number(
			"prior", "model_width", "onnx: the network's input width (the image is letterboxed into it)",
			[](DaemonConfig &c) -> int & { return c.motion.prior.model_spec.input_width; }, 8, 8192));
		o.push_back(number(
			"prior", "model_height", "onnx: the network's input height",
			[](DaemonConfig &c) -> int & { return c.motion.prior.model_spec.input_height; }, 8, 8192));
		o.push_back(number(
			"prior", "model_scale", "onnx: pixel values are multiplied by this (1/255: 0..1)",
			[](DaemonConfig &c) -> double & { return c.motion.prior.model_spec.input_scale; }, 1e-6, 1e3));
		o.push_back(boolean("prior", "model_rgb",
				    "onnx: the network wants RGB (false: BGR, as OpenCV's images)",
				    [](DaemonConfig &c) -> bool & { return c.motion.prior.model_spec.swap_rb; }));
		{
			Option classes{"prior", "model_classes",
				       "onnx: class:category pairs, category dynamic | potentially_dynamic (0 = COCO's "
				       "person)",
				       nullptr, nullptr};
			classes.set = [](const Value &v, DaemonConfig &c) {
				if (!v.is_string())
					throw std::invalid_argument(
						"must be a string, e.g. \"0:dynamic,56:potentially_dynamic\"");
				c.motion.prior.model_spec.classes = vision::parse_class_map(std::string(v.as_string()));
			};
			classes.show = [](const DaemonConfig &c) {
				return "\"" + vision::format_class_map(c.motion.prior.model_spec.classes) + "\"";
			};
			o.push_back(std::move(classes));
		}
		o.push_back(number(
			"prior", "model_min_confidence", "onnx detectors: the score a box needs (0..1)",
			[](DaemonConfig &c) -> double & { return c.motion.prior.model_spec.min_confidence; }, 0, 1));
		o.push_back(number(
			"prior", "model_nms_iou", "onnx detectors: boxes of one class overlapping more are one (IoU)",
			[](DaemonConfig &c) -> double & { return c.motion.prior.model_spec.nms_iou; }, 0, 1));
		o.push_back(number(
			"prior", "model_min_region_px", "onnx segmentation: smaller regions (image pixels) are dropped",
			[](DaemonConfig &c) -> int & { return c.motion.prior.model_spec.min_region_px; }, 1,
			100000000));
		o.push_back(number(
			"prior", "object_vote",
			"potentially dynamic objects: all their points are dynamic when this share of them is",
			[](DaemonConfig &c) -> double & { return c.motion.prior.object_vote; }, 0, 1));

		// [keyframes]: seed 001's keyframe selection, eqs. 6-7 (core/vision/keyframes.hpp)
		o.push_back(boolean("keyframes", "enabled", "mark keyframes (stereo/RGB-D: needs the metric pose)",
				    [](DaemonConfig &c) -> bool & { return c.motion.keyframes.enabled; }));
		o.push_back(number(
			"keyframes", "min_translation_m", "eq. 6: the camera moved this far since the last keyframe...",
			[](DaemonConfig &c) -> double & { return c.motion.keyframes.min_translation_m; }, 0, 1000));
		o.push_back(number(
			"keyframes", "min_rotation_deg", "eq. 6: ...or turned this much",
			[](DaemonConfig &c) -> double & { return c.motion.keyframes.min_rotation_deg; }, 0, 180));
		o.push_back(number(
			"keyframes", "max_covisibility",
			"eq. 7: and shares less than this fraction of its static points",
			[](DaemonConfig &c) -> double & { return c.motion.keyframes.max_covisibility; }, 0, 1));
		o.push_back(number(
			"keyframes", "min_new_points", "and sees at least this many static points the last one did not",
			[](DaemonConfig &c) -> int & { return c.motion.keyframes.min_new_points; }, 0, 100000));

		// [output]
		o.push_back(text("output", "socket", "Unix socket path for clients",
				 [](DaemonConfig &c) -> std::string & { return c.output.socket; }));
		{
			// Shown in TOML's octal form, as permissions are read.
			Option mode = number(
				"output", "socket_mode", "permissions of the socket file (TOML octal, e.g. 0o660)",
				[](DaemonConfig &c) -> int & { return c.output.socket_mode; }, 0, 0777);
			mode.show = [](const DaemonConfig &c) {
				char text[16];
				std::snprintf(text, sizeof(text), "0o%o", static_cast<unsigned>(c.output.socket_mode));
				return std::string(text);
			};
			o.push_back(std::move(mode));
		}
		o.push_back(number(
			"output", "client_queue", "messages queued per client; a slow client loses its oldest",
			[](DaemonConfig &c) -> int & { return c.output.client_queue; }, 1, 100000));
		o.push_back(number(
			"output", "client_queue_bytes", "bytes queued per client; a slow client loses its oldest",
			[](DaemonConfig &c) -> int & { return c.output.client_queue_bytes; }, 4096, 1 << 30));
		o.push_back(number(
			"output", "max_clients", "clients served at once; more are refused and counted",
			[](DaemonConfig &c) -> int & { return c.output.max_clients; }, 1, 100000));
		o.push_back(number(
			"output", "client_max_input", "bytes a client may send before it is dropped",
			[](DaemonConfig &c) -> int & { return c.output.client_max_input; }, 0, 1 << 30));
		o.push_back(number(
			"output", "status_interval_s", "seconds between status messages",
			[](DaemonConfig &c) -> double & { return c.output.status_interval_s; }, 0.05, 3600));
		o.push_back(text("output", "socket_group", "group owning the socket file; empty: the daemon's own",
				 [](DaemonConfig &c) -> std::string & { return c.output.socket_group; }));
		o.push_back(text_list(
			"output", "allow_users",
			"users (names or uids) who may read; both lists empty: anyone the socket mode lets in",
			[](DaemonConfig &c) -> std::vector<std::string> & { return c.output.allow_users; }));
		o.push_back(
			text_list("output", "allow_groups", "members of these groups (names or gids) may read",
				  [](DaemonConfig &c) -> std::vector<std::string> & { return c.output.allow_groups; }));
		// [record]: live recording beside the stream (daemon/live_recorder.hpp)
		o.push_back(text("record", "path",
				 "record every captured frame to this file while streaming (.srec, or .mcap: "
				 "frames, results and optional JPEG images, docs/mcap.md); empty: off",
				 [](DaemonConfig &c) -> std::string & { return c.record.path; }));
		o.push_back(number(
			"record", "buffer_frames",
			"frames waiting for the disk at most (more are counted, not recorded)",
			[](DaemonConfig &c) -> int & { return c.record.buffer_frames; }, 1, 1024));
		o.push_back(boolean("record", "sync", "force each frame to the disk before the next (power-cut safe)",
				    [](DaemonConfig &c) -> bool & { return c.record.sync; }));
		o.push_back(
			boolean("record", "images",
				"MCAP only: also JPEG images (foxglove.CompressedImage) so Foxglove shows the video",
				[](DaemonConfig &c) -> bool & { return c.record.images; }));
		o.push_back(boolean("record", "results", "MCAP only: also the processed results (/stereod/frames)",
				    [](DaemonConfig &c) -> bool & { return c.record.results; }));
		// [dds]: results as ROS 2 messages on DDS (daemon/dds/dds_publisher.hpp, docs/ros2.md)
		o.push_back(boolean("dds", "enabled",
				    "publish odom, groups, points and status on DDS as ROS 2 messages (docs/ros2.md)",
				    [](DaemonConfig &c) -> bool & { return c.dds.enabled; }));
		o.push_back(number(
			"dds", "domain", "DDS domain id (ROS_DOMAIN_ID of the ROS 2 machines that listen)",
			[](DaemonConfig &c) -> int & { return c.dds.domain; }, 0, 232));
		o.push_back(text("dds", "name",
				 "this board's name: topics are rt/stereod/<name>/{odom,groups,points,status} "
				 "(letters, digits, _; not starting with a digit)",
				 [](DaemonConfig &c) -> std::string & { return c.dds.name; }));
		o.push_back(text("dds", "qos",
				 "reliable (ROS 2's default: reliable, keep last 10) | sensor_data (best effort, keep "
				 "last 5)",
				 [](DaemonConfig &c) -> std::string & { return c.dds.qos; },
				 {"reliable", "sensor_data"}));
		o.push_back(text("dds", "frame_id",
				 "odom's header.frame_id: the world, which is the first frame's camera",
				 [](DaemonConfig &c) -> std::string & { return c.dds.frame_id; }));
		o.push_back(
			text("dds", "child_frame_id",
			     "the camera's frame (left rectified, x right, y down, z forward): odom's child, points' "
			     "and groups' frame",
			     [](DaemonConfig &c) -> std::string & { return c.dds.child_frame_id; }));
		// [log]
		o.push_back(text("log", "level", "trace | debug | info | warn | error",
				 [](DaemonConfig &c) -> std::string & { return c.log.level; },
				 {"trace", "debug", "info", "warn", "error"}));
		return o;
	}();
	return all;
}

const Option *find_option(const std::string &section, const std::string &key)
{
	for (const auto &option : options())
		if (option.section == section && option.key == key)
			return &option;
	return nullptr;
}

std::string where(const std::string &origin, const Value &v)
{
	const auto line = v.location().line();
	return line > 0 ? origin + ":" + std::to_string(line) : origin;
}

void apply_document(const Value &document, const std::string &origin, DaemonConfig &config)
{
	for (const auto &[section, table] : document.as_table()) {
		bool known_section = false;
		for (const auto &option : options())
			known_section = known_section || option.section == section;
		if (!known_section)
			throw ConfigError(where(origin, table) + ": unknown section or key '" + section + "'");
		if (!table.is_table())
			throw ConfigError(where(origin, table) + ": '" + section + "' must be a [section]");
		for (const auto &[key, value] : table.as_table()) {
			const Option *option = find_option(section, key);
			if (!option)
				throw ConfigError(where(origin, value) + ": unknown key '" + section + "." + key + "'");
			try {
				option->set(value, config);
			} catch (const std::invalid_argument &e) {
				throw ConfigError(where(origin, value) + ": " + section + "." + key + ": " + e.what());
			}
		}
	}
}

/// A config is a few kilobytes of flat tables. Anything far larger or nested deeper is refused before the
/// recursive-descent parser sees it: 7,000 nested arrays overflow its stack, a million inline tables burn
/// tens of seconds of CPU.
constexpr size_t kMaxConfigBytes = 1 << 20;
constexpr int kMaxNesting = 32;

/// TOML documents are UTF-8 (the spec requires it). Checked before toml11 sees the text: its 3.7 reads past
/// its buffer when a literal string holds invalid UTF-8 (found by fuzz_config). Throws ConfigError naming the
/// line of the first bad byte.
void check_utf8(const std::string &text, const std::string &origin)
{
	size_t line = 1;
	for (size_t i = 0; i < text.size();) {
		const auto byte = static_cast<unsigned char>(text[i]);
		if (byte < 0x80) {
			line += byte == '\n' ? 1 : 0;
			++i;
			continue;
		}
		// The length the lead byte announces, and the smallest code point that needs it (no overlong forms).
		const size_t length = byte >= 0xC2 && byte <= 0xDF   ? 2
				      : byte >= 0xE0 && byte <= 0xEF ? 3
				      : byte >= 0xF0 && byte <= 0xF4 ? 4
								     : 0;
		uint32_t code = length == 2 ? byte & 0x1FU : length == 3 ? byte & 0x0FU : byte & 0x07U;
		bool valid = length > 0 && i + length <= text.size();
		for (size_t k = 1; valid && k < length; ++k) {
			const auto next = static_cast<unsigned char>(text[i + k]);
			valid = (next & 0xC0U) == 0x80U;
			code = (code << 6U) | (next & 0x3FU);
		}
		valid = valid && !(length == 3 && code < 0x800) && !(length == 4 && code < 0x10000) &&
			!(code >= 0xD800 && code <= 0xDFFF) && code <= 0x10FFFF;
		if (!valid) {
			char hex[8];
			std::snprintf(hex, sizeof(hex), "0x%02X", byte);
			throw ConfigError(origin + ":" + std::to_string(line) + ": not valid UTF-8 (byte " + hex +
					  "); a TOML file is UTF-8");
		}
		i += length;
	}
}

/// Checks the nesting of arrays and inline tables, skipping strings and comments. Throws ConfigError naming
/// the line where the limit is passed.
void check_nesting(const std::string &text, const std::string &origin)
{
	int depth = 0;
	size_t line = 1;
	for (size_t i = 0; i < text.size(); ++i) {
		const char c = text[i];
		if (c == '\n') {
			++line;
		} else if (c == '#') {
			while (i + 1 < text.size() && text[i + 1] != '\n')
				++i;
		} else if (c == '"' || c == '\'') {
			const bool triple = text.compare(i, 3, std::string(3, c)) == 0;
			const std::string close = triple ? std::string(3, c) : std::string(1, c);
			size_t j = i + close.size();
			while (j < text.size() && text.compare(j, close.size(), close) != 0) {
				if (c == '"' && text[j] == '\\')
					++j; // an escaped character cannot close the string
				else if (text[j] == '\n')
					++line;
				++j;
			}
			i = std::min(text.size(), j + close.size()) - 1;
		} else if (c == '[' || c == '{') {
			if (++depth > kMaxNesting)
				throw ConfigError(origin + ":" + std::to_string(line) +
						  ": arrays or tables nested deeper than " +
						  std::to_string(kMaxNesting) + " levels");
		} else if (c == ']' || c == '}') {
			depth = std::max(0, depth - 1);
		}
	}
}

Value parse_toml(std::istream &in, const std::string &origin)
{
	std::string text;
	{
		std::ostringstream buffer;
		char chunk[65536];
		while (in.read(chunk, sizeof(chunk)) || in.gcount() > 0) {
			buffer.write(chunk, in.gcount());
			if (static_cast<size_t>(buffer.tellp()) > kMaxConfigBytes)
				throw ConfigError(origin + ": larger than " + std::to_string(kMaxConfigBytes >> 10) +
						  " KiB; not a stereod config");
		}
		text = buffer.str();
	}
	check_utf8(text, origin);
	check_nesting(text, origin);
	std::istringstream parsed(text);
	try {
		return toml::parse(parsed, origin);
	} catch (const toml::syntax_error &e) {
		// toml11's message spans several lines with a source excerpt; keep its first line.
		std::string what = e.what();
		const auto first = what.find('\n');
		if (first != std::string::npos)
			what = what.substr(0, first);
		if (what.rfind("[error] ", 0) == 0)
			what = what.substr(8);
		throw ConfigError(origin + ":" + std::to_string(e.location().line()) + ": syntax error: " + what);
	}
}

} // namespace

void load_config_file(const std::string &path, DaemonConfig &config)
{
	// A directory reads as a failed stream (std::bad_alloc in toml11), /dev/zero as an endless run of NULs:
	// only a regular file (or a link to one) is a config.
	std::error_code ec;
	const auto status = std::filesystem::status(path, ec);
	if (ec || !std::filesystem::exists(status))
		throw ConfigError(path + ": cannot read config file: no such file");
	if (!std::filesystem::is_regular_file(status))
		throw ConfigError(path + ": not a regular file; give a TOML config file");
	std::ifstream in(path, std::ios::binary);
	if (!in)
		throw ConfigError(path + ": cannot read config file");
	apply_document(parse_toml(in, path), path, config);
	validate(config, path);
}

void apply_override(const std::string &assignment, DaemonConfig &config)
{
	// A newline in a value would start a new TOML line and could set any other key.
	for (const char c : assignment)
		if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f)
			throw ConfigError("--set: control characters are not allowed in an override (" +
					  describe_cut(assignment) + ")");
	if (assignment.size() > kMaxConfigBytes)
		throw ConfigError("--set " + describe_cut(assignment) + ": larger than " +
				  std::to_string(kMaxConfigBytes >> 10) + " KiB");
	const auto eq = assignment.find('=');
	const auto dot = assignment.find('.');
	if (eq == std::string::npos || dot == std::string::npos || dot > eq)
		throw ConfigError("--set " + describe_cut(assignment) + ": expected section.key=value");
	const std::string section = assignment.substr(0, dot);
	const std::string key = assignment.substr(dot + 1, eq - dot - 1);
	std::string value = assignment.substr(eq + 1);
	const Option *option = find_option(section, key);
	if (!option)
		throw ConfigError("--set " + describe_cut(assignment) + ": unknown key '" +
				  describe_cut(section + "." + key) + "'");
	// Bare words are strings: --set source.driver=video (or aravis.left=127.0.0.1, which is no TOML number)
	// works without shell-quoted TOML quotes. Anything else is read as TOML.
	// TOML's prefixed integers (0o660 for a socket mode, 0x..., 0b...) are numbers, not words.
	const bool prefixed_integer = value.size() > 2 && value[0] == '0' &&
				      (value[1] == 'o' || value[1] == 'x' || value[1] == 'b') &&
				      value.find_first_not_of("0123456789abcdefABCDEF_", 2) == std::string::npos;
	const bool bare_word = !value.empty() && !prefixed_integer &&
			       value.find_first_of("\"'[{") == std::string::npos && value != "true" &&
			       value != "false" && value.find_first_not_of("0123456789+-.eE_") != std::string::npos;
	const bool dotted_number = value.find_first_not_of("0123456789.") == std::string::npos &&
				   std::count(value.begin(), value.end(), '.') > 1;
	if (bare_word || dotted_number)
		value = toml::format(Value(value));
	std::istringstream in("[" + section + "]\n" + key + " = " + value + "\n");
	apply_document(parse_toml(in, "--set " + section + "." + key), "--set", config);
	validate(config, "--set");
}

void validate(const DaemonConfig &config, const std::string &origin)
{
	// The socket path is checked here, with the rest of the config, not after the source has started.
	const std::string &socket = config.output.socket;
	if (socket.empty())
		throw ConfigError(origin + ": output.socket: must not be empty");
	if (socket.size() >= sizeof(sockaddr_un::sun_path))
		throw ConfigError(origin + ": output.socket: longer than " +
				  std::to_string(sizeof(sockaddr_un::sun_path) - 1) + " bytes (" +
				  describe_cut(socket) + ")");
	// A ROS 2 name token: it becomes part of the topic names, which ROS 2 tools must accept.
	const std::string &name = config.dds.name;
	const bool name_ok = !name.empty() && !std::isdigit(static_cast<unsigned char>(name[0])) &&
			     std::all_of(name.begin(), name.end(), [](char ch) {
				     return std::isalnum(static_cast<unsigned char>(ch)) || ch == '_';
			     });
	if (!name_ok)
		throw ConfigError(origin + ": dds.name: '" + describe_cut(name) +
				  "' is not a ROS 2 name token (letters, digits and _, not starting with a digit)");
	const auto &c = config.motion.classifier;
	if (std::abs(c.alpha + c.beta + c.gamma - 1.0) > 1e-6) {
		std::ostringstream msg;
		msg << origin << ": classifier.alpha + classifier.beta + classifier.gamma must be 1 (eq. 4), got "
		    << c.alpha + c.beta + c.gamma;
		throw ConfigError(msg.str());
	}
	const auto &stereo = config.motion.stereo;
	if (stereo.enabled && !stereo.right_features && !stereo.row_search)
		throw ConfigError(origin + ": stereo.right_features = false needs stereo.row_search = true (without "
					   "either there is nothing to match the left keypoints to)");
}

std::vector<std::string> changed_options(const DaemonConfig &a, const DaemonConfig &b)
{
	std::vector<std::string> changed;
	for (const auto &option : options())
		if (option.show(a) != option.show(b))
			changed.push_back(option.section + "." + option.key);
	return changed;
}

std::string default_config_text()
{
	const DaemonConfig defaults;
	std::ostringstream out;
	out << "# stereod configuration: every option at its default.\n"
	       "# Generated by `stereod --print-config`; docs/configuration.md explains each option.\n";
	std::string section;
	for (const auto &option : options()) {
		if (option.section != section) {
			section = option.section;
			out << "\n[" << section << "]\n";
		}
		out << "# " << option.help << "\n" << option.key << " = " << option.show(defaults) << "\n";
	}
	return out.str();
}

} // namespace stereod::daemon
