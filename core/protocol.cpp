#include "core/protocol.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <type_traits>

#include <nlohmann/json.hpp>

namespace stereod {

std::string_view to_string(PointLabel label) noexcept
{
	switch (label) {
	case PointLabel::Static:
		return "static";
	case PointLabel::Dynamic:
		return "dynamic";
	case PointLabel::Uncertain:
		return "uncertain";
	}
	return "uncertain";
}

namespace protocol {
namespace {

using nlohmann::json;

// Pixel coordinates to 0.01 px and times to 0.001 ms: enough for any consumer, and it keeps lines short.
// Dividing by the power of ten (not multiplying by 0.01) gives the double nearest the decimal, which the
// JSON writer then prints in its shortest form.
double round_to(double value, double step)
{
	const double scale = std::round(1.0 / step);
	return std::round(value * scale) / scale;
}

PointLabel parse_label(const std::string &text)
{
	if (text == "static")
		return PointLabel::Static;
	if (text == "dynamic")
		return PointLabel::Dynamic;
	if (text == "uncertain")
		return PointLabel::Uncertain;
	throw std::runtime_error("unknown point label '" + text + "'");
}

FrameStatus parse_status(const std::string &text)
{
	if (text == "ok")
		return FrameStatus::Ok;
	if (text == "incomplete")
		return FrameStatus::Incomplete;
	if (text == "corrupt")
		return FrameStatus::Corrupt;
	throw std::runtime_error("unknown frame status '" + text + "'");
}

} // namespace

std::string frame_message(const FrameResult &result)
{
	json message = {
		{"v", kVersion},
		{"type", "frame"},
		{"seq", result.seq},
		{"t_capture_ns", result.t_capture_ns},
		{"t_host_ns", result.t_host_ns},
		{"t_publish_ns", result.t_publish_ns},
		{"lr_skew_ns", result.lr_skew_ns},
		{"source", result.source},
		{"status", to_string(result.status)},
		{"width", result.width},
		{"height", result.height},
	};
	json timing = json::object();
	for (const auto &stage : result.timing)
		timing[stage.name] = round_to(stage.ms, 0.001);
	message["timing_ms"] = std::move(timing);

	json points = json::array();
	for (const auto &point : result.points) {
		json p = {{"u", round_to(point.u, 0.01)},
			  {"v", round_to(point.v, 0.01)},
			  {"label", to_string(point.label)},
			  {"pu", round_to(point.prev_u, 0.01)},
			  {"pv", round_to(point.prev_v, 0.01)}};
		if (point.track != 0)
			p["track"] = point.track;
		if (point.xyz_m)
			p["xyz_m"] = {round_to((*point.xyz_m)[0], 0.001), round_to((*point.xyz_m)[1], 0.001),
				      round_to((*point.xyz_m)[2], 0.001)};
		if (point.in_person)
			p["person"] = true;
		points.push_back(std::move(p));
	}
	message["points"] = std::move(points);

	if (result.ego) {
		const EgoMotion &ego = *result.ego;
		json e = {{"inliers", ego.inliers}};
		e["homography"] = ego.homography ? json(*ego.homography) : json(nullptr);
		if (ego.homography) {
			e["homography_inliers"] = ego.homography_inliers;
			e["homography_refined"] = ego.homography_refined;
		}
		if (ego.valid) {
			// 1e-7: a tenth of a micrometre, far below any pose's accuracy, and short on the wire.
			const auto matrix = [](const std::optional<std::array<double, 16>> &m) {
				if (!m)
					return json(nullptr);
				json a = json::array();
				for (double x : *m)
					a.push_back(round_to(x, 1e-7));
				return a;
			};
			e["valid"] = *ego.valid;
			e["T_prev_curr"] = matrix(ego.t_prev_curr);
			e["T_world_curr"] = matrix(ego.t_world_curr);
			if (!*ego.valid)
				e["reason"] = ego.reason;
		}
		if (ego.keyframe)
			e["keyframe"] = *ego.keyframe;
		if (ego.covisibility)
			e["covisibility"] = round_to(*ego.covisibility, 0.001);
		message["ego"] = std::move(e);
	} else {
		message["ego"] = nullptr;
	}
	if (result.stereo) {
		const StereoSummary &s = *result.stereo;
		message["stereo"] = {{"keypoints", s.keypoints},
				     {"matched", s.matched},
				     {"candidates", s.candidates},
				     {"outside_band", s.outside_band},
				     {"median_row_diff_px", round_to(s.median_row_diff_px, 0.001)},
				     {"row_search", s.row_search}};
	}

	json groups = json::array();
	for (const auto &group : result.groups) {
		json g = {
			{"id", group.id},
			{"box_px",
			 {round_to(group.box_px[0], 0.1), round_to(group.box_px[1], 0.1),
			  round_to(group.box_px[2], 0.1), round_to(group.box_px[3], 0.1)}},
			{"points", group.point_count},
			{"age_frames", group.age_frames},
			{"missed_frames", group.missed_frames},
			{"image_velocity_pxps",
			 {round_to(group.image_velocity_pxps[0], 0.01), round_to(group.image_velocity_pxps[1], 0.01)}}};
		const auto put3 = [&g](const char *key, const std::optional<std::array<double, 3>> &v) {
			if (v)
				g[key] = {round_to((*v)[0], 0.001), round_to((*v)[1], 0.001), round_to((*v)[2], 0.001)};
		};
		put3("position_m", group.position_m);
		put3("extent_m", group.extent_m);
		put3("velocity_mps", group.velocity_mps);
		put3("world_velocity_mps", group.world_velocity_mps);
		if (group.speed_mps)
			g["speed_mps"] = round_to(*group.speed_mps, 0.001);
		if (group.heading_rad)
			g["heading_rad"] = round_to(*group.heading_rad, 0.001);
		if (group.velocity_sigma_mps)
			g["velocity_sigma_mps"] = {round_to((*group.velocity_sigma_mps)[0], 0.001),
						   round_to((*group.velocity_sigma_mps)[1], 0.001)};
		if (group.speed_sigma_mps)
			g["speed_sigma_mps"] = round_to(*group.speed_sigma_mps, 0.001);
		if (!group.class_name.empty())
			g["class"] = group.class_name;
		groups.push_back(std::move(g));
	}
	message["groups"] = std::move(groups);
	// The prior's regions: people (its dynamic category) and, with a model that knows them, objects.
	const auto regions = [](const std::vector<PersonRegion> &list) {
		json out = json::array();
		for (const auto &r : list) {
			json item = {{"box_px",
				      {round_to(r.box_px[0], 0.1), round_to(r.box_px[1], 0.1),
				       round_to(r.box_px[2], 0.1), round_to(r.box_px[3], 0.1)}},
				     {"score", round_to(r.score, 0.01)},
				     {"age_frames", r.age_frames}};
			if (r.class_id >= 0)
				item["class_id"] = r.class_id;
			out.push_back(std::move(item));
		}
		return out;
	};
	if (!result.people.empty())
		message["people"] = regions(result.people);
	if (!result.objects.empty())
		message["objects"] = regions(result.objects);
	return message.dump();
}

namespace {

/// A number from outside bytes as T, refused (std::runtime_error) when it is not a number or T cannot hold it:
/// nlohmann's own conversion is a static_cast, undefined for 1e24 as an int or 1e300 as a float (found by
/// fuzz_frame_message).
template <typename T>
T checked(const json &j)
{
	if (!j.is_number())
		throw std::runtime_error("not a number: " + j.dump().substr(0, 40));
	if constexpr (std::is_floating_point_v<T>) {
		const double d = j.get<double>();
		if (std::isfinite(d) && std::abs(d) > static_cast<double>(std::numeric_limits<T>::max()))
			throw std::runtime_error("number out of range: " + j.dump().substr(0, 40));
		return static_cast<T>(d);
	} else {
		if (j.is_number_unsigned()) {
			const auto u = j.get<uint64_t>();
			if (u > static_cast<uint64_t>(std::numeric_limits<T>::max()))
				throw std::runtime_error("number out of range: " + j.dump().substr(0, 40));
			return static_cast<T>(u);
		}
		if (j.is_number_integer()) {
			const auto i = j.get<int64_t>();
			if constexpr (std::is_unsigned_v<T>) {
				if (i < 0 ||
				    static_cast<uint64_t>(i) > static_cast<uint64_t>(std::numeric_limits<T>::max()))
					throw std::runtime_error("number out of range: " + j.dump().substr(0, 40));
			} else if (i < static_cast<int64_t>(std::numeric_limits<T>::lowest()) ||
				   i > static_cast<int64_t>(std::numeric_limits<T>::max())) {
				throw std::runtime_error("number out of range: " + j.dump().substr(0, 40));
			}
			return static_cast<T>(i);
		}
		const double d = j.get<double>();
		// The bounds as doubles: 2^63 and friends are exact; a value must lie strictly inside them.
		if (!(d >= static_cast<double>(std::numeric_limits<T>::lowest()) &&
		      d < static_cast<double>(std::numeric_limits<T>::max())))
			throw std::runtime_error("number out of range: " + j.dump().substr(0, 40));
		return static_cast<T>(d);
	}
}

template <typename T>
T field(const json &object, const char *key)
{
	return checked<T>(object.at(key));
}

template <typename T>
T field_or(const json &object, const char *key, T fallback)
{
	const auto it = object.find(key);
	return it == object.end() ? fallback : checked<T>(*it);
}

template <typename T, size_t N>
std::array<T, N> array_field(const json &j)
{
	if (!j.is_array() || j.size() != N)
		throw std::runtime_error("not an array of " + std::to_string(N) + " numbers");
	std::array<T, N> out{};
	for (size_t i = 0; i < N; ++i)
		out[i] = checked<T>(j[i]);
	return out;
}

} // namespace

FrameResult parse_frame_message(const json &message)
{
	if (message.at("type").get<std::string>() != "frame")
		throw std::runtime_error("not a frame message");
	if (field<int>(message, "v") != kVersion)
		throw std::runtime_error("unsupported protocol version " + message.at("v").dump());
	FrameResult result;
	result.seq = field<uint64_t>(message, "seq");
	result.t_capture_ns = field<int64_t>(message, "t_capture_ns");
	result.t_host_ns = field<int64_t>(message, "t_host_ns");
	result.t_publish_ns = field<int64_t>(message, "t_publish_ns");
	result.lr_skew_ns = field_or<int64_t>(message, "lr_skew_ns", 0);
	result.source = message.at("source").get<std::string>();
	result.status = parse_status(message.at("status").get<std::string>());
	result.width = field_or<int>(message, "width", 0);
	result.height = field_or<int>(message, "height", 0);
	for (const auto &[name, ms] : message.at("timing_ms").items())
		result.timing.push_back({name, checked<double>(ms)});
	for (const auto &p : message.at("points")) {
		LabelledPoint point;
		point.u = field<float>(p, "u");
		point.v = field<float>(p, "v");
		point.label = parse_label(p.at("label").get<std::string>());
		point.prev_u = field_or<float>(p, "pu", point.u);
		point.prev_v = field_or<float>(p, "pv", point.v);
		point.track = field_or<uint64_t>(p, "track", 0);
		if (p.contains("xyz_m"))
			point.xyz_m = array_field<float, 3>(p.at("xyz_m"));
		point.in_person = p.value("person", false);
		result.points.push_back(point);
	}
	if (const auto &ego = message.at("ego"); !ego.is_null()) {
		EgoMotion e;
		e.inliers = field<int>(ego, "inliers");
		if (ego.contains("homography") && !ego.at("homography").is_null()) {
			e.homography = array_field<double, 9>(ego.at("homography"));
			e.homography_inliers = field_or<int>(ego, "homography_inliers", e.inliers);
			e.homography_refined = ego.value("homography_refined", true);
		}
		if (ego.contains("valid")) {
			e.valid = ego.at("valid").get<bool>();
			e.reason = ego.value("reason", std::string());
			for (const auto &[key, field] :
			     {std::pair{"T_prev_curr", &e.t_prev_curr}, std::pair{"T_world_curr", &e.t_world_curr}})
				if (ego.contains(key) && !ego.at(key).is_null())
					*field = array_field<double, 16>(ego.at(key));
		}
		if (ego.contains("keyframe"))
			e.keyframe = ego.at("keyframe").get<bool>();
		if (ego.contains("covisibility"))
			e.covisibility = field<double>(ego, "covisibility");
		result.ego = e;
	}
	if (message.contains("stereo")) {
		const auto &s = message.at("stereo");
		result.stereo = StereoSummary{field<int>(s, "keypoints"),
					      field<int>(s, "matched"),
					      field<int>(s, "candidates"),
					      field<int>(s, "outside_band"),
					      field<float>(s, "median_row_diff_px"),
					      s.contains("row_search") ? field<int>(s, "row_search") : 0};
	}
	for (const auto &g : message.at("groups")) {
		TargetGroup group;
		group.id = field<int>(g, "id");
		group.box_px = array_field<float, 4>(g.at("box_px"));
		group.point_count = field<int>(g, "points");
		group.age_frames = field<int>(g, "age_frames");
		group.missed_frames = field_or<int>(g, "missed_frames", 0);
		group.image_velocity_pxps = array_field<float, 2>(g.at("image_velocity_pxps"));
		const auto get3 = [&g](const char *key) -> std::optional<std::array<double, 3>> {
			if (!g.contains(key))
				return std::nullopt;
			return array_field<double, 3>(g.at(key));
		};
		group.position_m = get3("position_m");
		group.extent_m = get3("extent_m");
		group.velocity_mps = get3("velocity_mps");
		group.world_velocity_mps = get3("world_velocity_mps");
		if (g.contains("speed_mps"))
			group.speed_mps = field<double>(g, "speed_mps");
		if (g.contains("heading_rad"))
			group.heading_rad = field<double>(g, "heading_rad");
		if (g.contains("velocity_sigma_mps"))
			group.velocity_sigma_mps = array_field<double, 2>(g.at("velocity_sigma_mps"));
		if (g.contains("speed_sigma_mps"))
			group.speed_sigma_mps = field<double>(g, "speed_sigma_mps");
		group.class_name = g.value("class", std::string());
		result.groups.push_back(group);
	}
	for (const auto &[key, list] : {std::pair{"people", &result.people}, std::pair{"objects", &result.objects}}) {
		if (!message.contains(key))
			continue;
		for (const auto &p : message.at(key)) {
			PersonRegion region;
			region.box_px = array_field<float, 4>(p.at("box_px"));
			region.score = field_or<float>(p, "score", 0.0F);
			region.age_frames = field_or<int>(p, "age_frames", 0);
			region.class_id = field_or<int>(p, "class_id", -1);
			list->push_back(region);
		}
	}
	return result;
}

std::string status_message(const StatusReport &status)
{
	json message = {
		{"v", kVersion},
		{"type", "status"},
		{"t_host_ns", status.t_host_ns},
		{"uptime_s", round_to(status.uptime_s, 0.001)},
		{"source", status.source},
		{"source_state", status.source_state},
		{"fps",
		 {{"capture", round_to(status.capture_fps, 0.01)}, {"publish", round_to(status.publish_fps, 0.01)}}},
		{"frames", {{"captured", status.frames_captured}, {"published", status.frames_published}}},
		{"drops", status.drops},
		{"latency_ms",
		 {{"capture_to_publish",
		   {{"p50", round_to(status.capture_to_publish.p50_ms, 0.001)},
		    {"p90", round_to(status.capture_to_publish.p90_ms, 0.001)},
		    {"p99", round_to(status.capture_to_publish.p99_ms, 0.001)},
		    {"max", round_to(status.capture_to_publish.max_ms, 0.001)},
		    {"samples", status.capture_to_publish.samples}}}}},
		{"clients", status.clients},
	};
	if (!status.device.empty())
		message["device"] = status.device;
	if (status.stereo)
		message["stereo"] = {{"frames", status.stereo->frames},
				     {"row_diff_px", round_to(status.stereo->row_diff_px, 0.001)},
				     {"outside_band_fraction", round_to(status.stereo->outside_band_fraction, 0.0001)},
				     {"drifted", status.stereo->drifted}};
	if (status.recording) {
		const auto &r = *status.recording;
		message["recording"] = {{"path", r.path},
					{"state", r.state},
					{"frames", r.frames},
					{"bytes", r.bytes},
					{"dropped", r.dropped}};
		if (!r.error.empty())
			message["recording"]["error"] = r.error;
	}
	if (status.dds) {
		const auto &d = *status.dds;
		message["dds"] = {{"name", d.name},
				  {"domain", d.domain},
				  {"frames_published", d.frames_published},
				  {"frames_dropped", d.frames_dropped},
				  {"write_errors", d.write_errors},
				  {"publish_ms_mean", round_to(d.publish_ms_mean, 0.001)},
				  {"publish_ms_max", round_to(d.publish_ms_max, 0.001)}};
	}
	return message.dump();
}

std::string lag_message(int64_t t_host_ns, uint64_t dropped_total, uint64_t dropped_since_last)
{
	return json{{"v", kVersion},
		    {"type", "lag"},
		    {"t_host_ns", t_host_ns},
		    {"dropped", dropped_since_last},
		    {"dropped_total", dropped_total}}
		.dump();
}

std::string error_message(int64_t t_host_ns, const std::string &what)
{
	return json{{"v", kVersion}, {"type", "error"}, {"t_host_ns", t_host_ns}, {"error", what}}.dump();
}

std::string hello_message(int64_t t_host_ns, const std::string &source, int width, int height)
{
	return json{{"v", kVersion},	{"type", "hello"}, {"t_host_ns", t_host_ns},
		    {"source", source}, {"width", width},  {"height", height}}
		.dump();
}

} // namespace protocol
} // namespace stereod

namespace stereod::protocol {

std::string_view frame_json_schema()
{
	// Kept beside frame_message(): a field added there belongs here too (test_protocol checks every field
	// of a full message is described).
	return R"schema({
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "stereod.Frame",
  "description": "One processed frame from stereod (protocol version 1, docs/protocol.md)",
  "type": "object",
  "required": ["v", "type", "seq", "t_capture_ns", "t_host_ns", "t_publish_ns", "source", "status", "width", "height", "points", "groups"],
  "properties": {
    "v": {"type": "integer", "const": 1},
    "type": {"type": "string", "const": "frame"},
    "seq": {"type": "integer", "minimum": 0},
    "t_capture_ns": {"type": "integer", "description": "exposure time on the source's clock, ns"},
    "t_host_ns": {"type": "integer", "description": "CLOCK_MONOTONIC when the frame was complete on the host, ns"},
    "t_publish_ns": {"type": "integer", "description": "CLOCK_MONOTONIC when the result left the pipeline, ns"},
    "lr_skew_ns": {"type": "integer"},
    "source": {"type": "string"},
    "status": {"type": "string", "enum": ["ok", "incomplete", "corrupt"]},
    "width": {"type": "integer"},
    "height": {"type": "integer"},
    "timing_ms": {"type": "object", "additionalProperties": {"type": "number"}},
    "points": {
      "type": "array",
      "items": {
        "type": "object",
        "required": ["u", "v", "label"],
        "properties": {
          "u": {"type": "number"}, "v": {"type": "number"},
          "label": {"type": "string", "enum": ["static", "dynamic", "uncertain"]},
          "pu": {"type": "number"}, "pv": {"type": "number"},
          "track": {"type": "integer"},
          "xyz_m": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3},
          "person": {"type": "boolean"}
        }
      }
    },
    "ego": {
      "type": ["object", "null"],
      "properties": {
        "inliers": {"type": "integer"},
        "homography": {"type": ["array", "null"], "items": {"type": "number"}},
        "homography_inliers": {"type": "integer"},
        "homography_refined": {"type": "boolean"},
        "valid": {"type": "boolean"},
        "reason": {"type": "string"},
        "T_prev_curr": {"type": ["array", "null"], "items": {"type": "number"}, "minItems": 16, "maxItems": 16},
        "T_world_curr": {"type": ["array", "null"], "items": {"type": "number"}, "minItems": 16, "maxItems": 16},
        "keyframe": {"type": "boolean"},
        "covisibility": {"type": "number"}
      }
    },
    "stereo": {
      "type": "object",
      "properties": {
        "keypoints": {"type": "integer"}, "matched": {"type": "integer"}, "candidates": {"type": "integer"},
        "outside_band": {"type": "integer"}, "median_row_diff_px": {"type": "number"},
        "row_search": {"type": "integer"}
      }
    },
    "groups": {
      "type": "array",
      "items": {
        "type": "object",
        "required": ["id", "box_px", "points"],
        "properties": {
          "id": {"type": "integer"},
          "box_px": {"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4},
          "points": {"type": "integer"},
          "age_frames": {"type": "integer"},
          "missed_frames": {"type": "integer"},
          "image_velocity_pxps": {"type": "array", "items": {"type": "number"}},
          "position_m": {"type": "array", "items": {"type": "number"}},
          "extent_m": {"type": "array", "items": {"type": "number"}},
          "velocity_mps": {"type": "array", "items": {"type": "number"}},
          "world_velocity_mps": {"type": "array", "items": {"type": "number"}},
          "speed_mps": {"type": "number"},
          "heading_rad": {"type": "number"},
          "velocity_sigma_mps": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
          "speed_sigma_mps": {"type": "number"},
          "class": {"type": "string"}
        }
      }
    },
    "people": {"$ref": "#/$defs/prior_regions"},
    "objects": {"$ref": "#/$defs/prior_regions"}
  },
  "$defs": {
    "prior_regions": {
      "description": "the person prior's regions: people (dynamic category), objects (potentially dynamic)",
      "type": "array",
      "items": {
        "type": "object",
        "properties": {
          "box_px": {"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4},
          "score": {"type": "number"},
          "age_frames": {"type": "integer"},
          "class_id": {"type": "integer"}
        }
      }
    }
  }
})schema";
}

} // namespace stereod::protocol
