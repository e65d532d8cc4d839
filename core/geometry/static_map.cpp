#include "core/geometry/static_map.hpp"

#include <algorithm>
#include <cmath>

namespace stereod::geometry {
namespace {

/// 21 bits per axis, centred: +-1 million voxels (50 km at 5 cm) each way.
int64_t voxel_key(const cv::Vec3d &p, double voxel_m)
{
	int64_t key = 0;
	for (int axis = 0; axis < 3; ++axis) {
		const auto index = static_cast<int64_t>(std::floor(p[axis] / voxel_m)) + (int64_t{1} << 20);
		key = (key << 21) | (index & ((int64_t{1} << 21) - 1));
	}
	return key;
}

} // namespace

StaticMap::StaticMap(StaticMapParams params) : params_(params)
{
}

int StaticMap::add(const FrameResult &result, const cv::Mat &left)
{
	if (!result.ego || !result.ego->valid.value_or(false) || !result.ego->t_world_curr)
		return 0;
	const auto &t = *result.ego->t_world_curr;
	const cv::Matx33d r(t[0], t[1], t[2], t[4], t[5], t[6], t[8], t[9], t[10]);
	const cv::Vec3d translation(t[3], t[7], t[11]);
	++frames_used_;
	int added = 0;
	for (const auto &point : result.points) {
		if (point.label != PointLabel::Static || !point.xyz_m)
			continue;
		const auto &xyz = *point.xyz_m;
		if (!std::isfinite(xyz[2]) || xyz[2] <= 0 || xyz[2] > params_.max_depth_m)
			continue;
		const cv::Vec3d world = r * cv::Vec3d(xyz[0], xyz[1], xyz[2]) + translation;
		Voxel &voxel = voxels_[voxel_key(world, params_.voxel_m)];
		voxel.sum += world;
		++voxel.points;
		if (voxel.last_frame != result.seq + 1) { // +1: seq 0 is a valid frame
			voxel.last_frame = result.seq + 1;
			++voxel.observations;
		}
		const int u = static_cast<int>(std::lround(point.u)), v = static_cast<int>(std::lround(point.v));
		if (!left.empty() && u >= 0 && v >= 0 && u < left.cols && v < left.rows) {
			voxel.colour_sum += left.channels() == 3 ? cv::Vec3d(left.at<cv::Vec3b>(v, u))
								 : cv::Vec3d::all(left.at<uint8_t>(v, u));
			++voxel.coloured;
		}
		++added;
	}
	return added;
}

std::vector<MapPoint> StaticMap::points() const
{
	std::vector<std::pair<int64_t, MapPoint>> kept;
	for (const auto &[key, voxel] : voxels_) {
		if (voxel.observations < params_.min_observations)
			continue;
		MapPoint p;
		const cv::Vec3d mean = voxel.sum / voxel.points;
		p.xyz_m = cv::Vec3f(static_cast<float>(mean[0]), static_cast<float>(mean[1]),
				    static_cast<float>(mean[2]));
		if (voxel.coloured > 0) {
			const cv::Vec3d c = voxel.colour_sum / voxel.coloured;
			p.colour = cv::Vec3b(cv::saturate_cast<uint8_t>(c[0]), cv::saturate_cast<uint8_t>(c[1]),
					     cv::saturate_cast<uint8_t>(c[2]));
		}
		p.observations = voxel.observations;
		kept.emplace_back(key, p);
	}
	// In grid order, so the same results always write the same file.
	std::sort(kept.begin(), kept.end(), [](const auto &a, const auto &b) { return a.first < b.first; });
	std::vector<MapPoint> out;
	out.reserve(kept.size());
	for (const auto &[key, p] : kept)
		out.push_back(p);
	return out;
}

} // namespace stereod::geometry
