#pragma once
// The static scene as a point cloud, movers left out (seed 001, Fig. 6b): every point a frame labels `static`
// and measured in depth, carried into the world (the first frame's camera) by that frame's pose, and merged
// on a voxel grid. A voxel is kept once it has been seen in `min_observations` frames, so a point measured
// once (a bad depth, a mover's point mislabelled in one frame) does not make the map. Pure: results in,
// points out; `stereoctl map` writes the PLY.
//
// Every frame with a valid pose contributes (there are no keyframes yet: the voxel grid already bounds the
// map's size by the space it covers, not by the frames).
#include <cstdint>
#include <optional>
#include <unordered_map>
#include <vector>

#include <opencv2/core.hpp>

#include "core/result.hpp"

namespace stereod::geometry {

struct StaticMapParams {
	double voxel_m = 0.05;	   ///< grid cell edge
	int min_observations = 2;  ///< frames a voxel must be seen in to be kept
	double max_depth_m = 20.0; ///< farther points are too uncertain in depth to place
};

struct MapPoint {
	cv::Vec3f xyz_m;		 ///< mean of the voxel's points, world frame
	cv::Vec3b colour{128, 128, 128}; ///< B,G,R mean of the image under them (grey when none was given)
	int observations = 0;
};

class StaticMap
{
public:
	explicit StaticMap(StaticMapParams params = {});

	/// Adds one frame's static points with depth. `left` (optional, BGR or grey, the image the result's
	/// pixel coordinates refer to) colours them. A frame without a valid pose adds nothing. Returns how
	/// many points were added.
	int add(const FrameResult &result, const cv::Mat &left = {});

	/// The voxels seen at least min_observations times.
	[[nodiscard]] std::vector<MapPoint> points() const;
	[[nodiscard]] uint64_t frames_used() const noexcept { return frames_used_; }

private:
	struct Voxel {
		cv::Vec3d sum{0, 0, 0};
		cv::Vec3d colour_sum{0, 0, 0};
		int points = 0;
		int coloured = 0;
		int observations = 0;
		uint64_t last_frame = 0; ///< so several points of one frame in one voxel count one observation
	};
	StaticMapParams params_;
	std::unordered_map<int64_t, Voxel> voxels_;
	uint64_t frames_used_ = 0;
};

} // namespace stereod::geometry
