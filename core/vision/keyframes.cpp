#include "core/vision/keyframes.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <unordered_map>

namespace stereod::vision {

double covisibility(std::span<const StaticObservation> current, const geometry::Pose &world_from_curr,
		    const Keyframe &keyframe, const geometry::StereoRig &rig, const KeyframeParams &params)
{
	if (current.empty())
		return 0;
	// The keyframe's points in this camera, bucketed by pixel on a grid of match_px cells.
	const double cell = std::max(params.match_px, 0.5);
	const geometry::Pose curr_from_world = world_from_curr.inverse();
	struct Projected {
		cv::Point2d px;
		double z;
	};
	std::unordered_map<int64_t, std::vector<Projected>> grid;
	const auto key = [](int64_t cx, int64_t cy) { return (cx << 32) ^ (cy & 0xffffffff); };
	for (const cv::Vec3f &w : keyframe.static_world) {
		const cv::Vec3d c = curr_from_world * cv::Vec3d(w[0], w[1], w[2]);
		if (!(c[2] > 0))
			continue;
		const auto px = rig.project(c);
		if (!px)
			continue;
		grid[key(static_cast<int64_t>(std::floor(px->x / cell)),
			 static_cast<int64_t>(std::floor(px->y / cell)))]
			.push_back({*px, c[2]});
	}
	size_t common = 0;
	const double r2 = params.match_px * params.match_px;
	for (const StaticObservation &o : current) {
		const auto cx = static_cast<int64_t>(std::floor(o.px.x / cell));
		const auto cy = static_cast<int64_t>(std::floor(o.px.y / cell));
		bool seen = false;
		for (int64_t dy = -1; dy <= 1 && !seen; ++dy)
			for (int64_t dx = -1; dx <= 1 && !seen; ++dx) {
				const auto it = grid.find(key(cx + dx, cy + dy));
				if (it == grid.end())
					continue;
				for (const Projected &p : it->second) {
					const double ex = p.px.x - o.px.x;
					const double ey = p.px.y - o.px.y;
					if (ex * ex + ey * ey <= r2 &&
					    std::abs(p.z - o.xyz[2]) <= params.depth_tolerance * o.xyz[2]) {
						seen = true;
						break;
					}
				}
			}
		common += seen ? 1 : 0;
	}
	return static_cast<double>(common) / static_cast<double>(current.size());
}

KeyframeDecision decide_keyframe(const Keyframe &last, const geometry::Pose &world_from_curr,
				 std::span<const StaticObservation> current, const geometry::StereoRig &rig,
				 const KeyframeParams &params)
{
	KeyframeDecision d;
	const geometry::Pose last_from_curr = last.world_from_camera.inverse() * world_from_curr;
	d.translation_m = last_from_curr.distance();
	d.rotation_deg = last_from_curr.angle() * 180.0 / std::numbers::pi;
	d.moved = d.translation_m > params.min_translation_m || d.rotation_deg > params.min_rotation_deg;
	d.covisibility = covisibility(current, world_from_curr, last, rig, params);
	d.new_points = static_cast<int>(std::lround((1.0 - d.covisibility) * static_cast<double>(current.size())));
	d.keyframe = d.moved && d.covisibility < params.max_covisibility && d.new_points >= params.min_new_points;
	return d;
}

Keyframe make_keyframe(uint64_t seq, const geometry::Pose &world_from_curr, std::span<const StaticObservation> current)
{
	Keyframe k{seq, world_from_curr, {}};
	k.static_world.reserve(current.size());
	for (const StaticObservation &o : current) {
		const cv::Vec3d w = world_from_curr * cv::Vec3d(o.xyz[0], o.xyz[1], o.xyz[2]);
		k.static_world.emplace_back(static_cast<float>(w[0]), static_cast<float>(w[1]),
					    static_cast<float>(w[2]));
	}
	return k;
}

} // namespace stereod::vision
