#include "daemon/config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>

#include <toml.hpp>

namespace stereod::daemon {
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

/// ReplayRate is kept as an enum in the source config; the file names it.
Option replay_rate()
{
	Option o{"source", "rate", "file sources: recorded (original spacing) | fast | step (Enter per frame)", nullptr,
		 nullptr};
	o.set = [](const Value &v, DaemonConfig &c) {
		const std::string s = v.is_string() ? std::string(v.as_string()) : std::string();
		if (s == "recorded")
			c.source.rate = drivers::ReplayRate::Recorded;
		else if (s == "fast")
			c.source.rate = drivers::ReplayRate::Fast;
		else if (s == "step")
			c.source.rate = drivers::ReplayRate::Step;
		else
			throw std::invalid_argument("must be one of recorded, fast, step");
	};
	o.show = [](const DaemonConfig &c) {
		switch (c.source.rate) {
		case drivers::ReplayRate::Recorded:
			return std::string("\"recorded\"");
		case drivers::ReplayRate::Step:
			return std::string("\"step\"");
		case drivers::ReplayRate::Fast:
			break;
		}
		return std::string("\"fast\"");
	};
	return o;
}

const std::vector<Option> &options()
{
	static const std::vector<Option> all = [] {
		std::vector<Option> o;
		// [source]
		o.push_back(text("source", "driver",
				 "capture driver: sim | replay | video | kitti | euroc | tum | folder",
				 [](DaemonConfig &c) -> std::string & { return c.source.driver; },
				 {"sim", "replay", "video", "kitti", "euroc", "tum", "folder"}));
		o.push_back(text("source", "path", "file or folder for the file drivers",
				 [](DaemonConfig &c) -> std::string & { return c.source.path; }));
		o.push_back(replay_rate());
		o.push_back(boolean("source", "realtime", "pace generated sources (sim) at their frame rate",
				    [](DaemonConfig &c) -> bool & { return c.source.realtime; }));
		o.push_back(number(
			"source", "fps", "frame rate for inputs that state none (folder pairs); 0 = theirs",
			[](DaemonConfig &c) -> double & { return c.source.fps; }, 0, 1000));
		// [sim]
		o.push_back(text("sim", "scene",
				 "default | static_near | static_far | moving_one | moving_many | toward",
				 [](DaemonConfig &c) -> std::string & { return c.source.sim.scene; },
				 {"default", "static_near", "static_far", "moving_one", "moving_many", "toward"}));
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
		o.push_back(text("pipeline", "overflow", "when processing falls behind: auto | drop-oldest | block",
				 [](DaemonConfig &c) -> std::string & { return c.pipeline.overflow; },
				 {"auto", "drop-oldest", "block"}));
		// [features]
		o.push_back(boolean("features", "enabled", "run feature classification (seed 000)",
				    [](DaemonConfig &c) -> bool & { return c.motion.enabled; }));
		{
			Option detector{"features", "detector", "orb (OpenCV) | surf (this project's SURF)", nullptr,
					nullptr};
			detector.set = [](const Value &v, DaemonConfig &c) {
				const std::string name = v.is_string() ? std::string(v.as_string()) : std::string();
				if (name == "orb")
					c.motion.features.detector = vision::Detector::Orb;
				else if (name == "surf")
					c.motion.features.detector = vision::Detector::Surf;
				else
					throw std::invalid_argument("must be one of orb, surf");
			};
			detector.show = [](const DaemonConfig &c) {
				return std::string(c.motion.features.detector == vision::Detector::Orb ? "\"orb\""
												       : "\"surf\"");
			};
			o.push_back(std::move(detector));
		}
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
		// [classifier]
		o.push_back(number(
			"classifier", "ransac_threshold_px", "RANSAC inlier distance, pixels",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.ransac_threshold_px; }, 0.1, 50));
		o.push_back(number(
			"classifier", "reprojection_sigma_px", "feature position noise for eq. 1, pixels",
			[](DaemonConfig &c) -> double & { return c.motion.classifier.reprojection_sigma_px; }, 0.05,
			20));
		o.push_back(number(
			"classifier", "reprojection_chi2", "Mahalanobis gate on eq. 1 (chi-square, 4 dof)",
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
		// [memory]: beyond the seed (core/vision/temporal.hpp)
		o.push_back(number(
			"memory", "window_s", "time constant of each point's remembered own motion; 0 = seed only",
			[](DaemonConfig &c) -> double & { return c.motion.temporal.window_s; }, 0, 60));
		o.push_back(number(
			"memory", "chi2", "gate on the remembered own motion (chi-square, 2 dof)",
			[](DaemonConfig &c) -> double & { return c.motion.temporal.chi2; }, 0.1, 1000));
		o.push_back(number(
			"memory", "min_age", "frames a point is followed before its memory may label it",
			[](DaemonConfig &c) -> int & { return c.motion.temporal.min_age; }, 1, 10000));

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
			[](DaemonConfig &c) -> int & { return c.output.client_queue; }, 1, 1000000));
		o.push_back(number(
			"output", "client_max_input", "bytes a client may send before it is dropped",
			[](DaemonConfig &c) -> int & { return c.output.client_max_input; }, 0, 1 << 30));
		o.push_back(number(
			"output", "status_interval_s", "seconds between status messages",
			[](DaemonConfig &c) -> double & { return c.output.status_interval_s; }, 0.05, 3600));
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

Value parse_toml(std::istream &in, const std::string &origin)
{
	try {
		return toml::parse(in, origin);
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
	std::ifstream in(path, std::ios::binary);
	if (!in)
		throw ConfigError(path + ": cannot read config file");
	apply_document(parse_toml(in, path), path, config);
	validate(config, path);
}

void apply_override(const std::string &assignment, DaemonConfig &config)
{
	const auto eq = assignment.find('=');
	const auto dot = assignment.find('.');
	if (eq == std::string::npos || dot == std::string::npos || dot > eq)
		throw ConfigError("--set " + assignment + ": expected section.key=value");
	const std::string section = assignment.substr(0, dot);
	const std::string key = assignment.substr(dot + 1, eq - dot - 1);
	std::string value = assignment.substr(eq + 1);
	const Option *option = find_option(section, key);
	if (!option)
		throw ConfigError("--set " + assignment + ": unknown key '" + section + "." + key + "'");
	// Bare words are strings: --set source.driver=video works without shell-quoted TOML quotes.
	const bool bare_word = !value.empty() && value.find_first_of("\"'[{") == std::string::npos && value != "true" &&
			       value != "false" && value.find_first_not_of("0123456789+-.eE_") != std::string::npos;
	if (bare_word)
		value = toml::format(Value(value));
	std::istringstream in("[" + section + "]\n" + key + " = " + value + "\n");
	apply_document(parse_toml(in, "--set " + section + "." + key), "--set", config);
	validate(config, "--set");
}

void validate(const DaemonConfig &config, const std::string &origin)
{
	const auto &c = config.motion.classifier;
	if (std::abs(c.alpha + c.beta + c.gamma - 1.0) > 1e-6) {
		std::ostringstream msg;
		msg << origin << ": classifier.alpha + classifier.beta + classifier.gamma must be 1 (eq. 4), got "
		    << c.alpha + c.beta + c.gamma;
		throw ConfigError(msg.str());
	}
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
