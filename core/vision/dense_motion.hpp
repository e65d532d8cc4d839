#pragma once
// Seed 002's global flow (section 3.2): motion measured everywhere in the image, not only at feature points,
// so that a mover whose corners the feature matching misses or mislabels still shows as a region of strong
// motion. Two ways to the same output, a flow vector per cell of a regular grid:
//   PyrLk  the seed's pyramidal Lucas-Kanade: window 7 on 3 pyramid levels at every grid point, a point whose
//          gradient matrix is weaker than the seed's 0.001 (OpenCV's minimum-eigenvalue test) set to zero;
//   Dis    OpenCV's DIS flow (ultrafast preset) over the whole reduced image, averaged over each cell.
// Both run on the left image scaled by `scale` (made once per frame in the extract stage). Each cell then
// becomes a MotionPoint: its flow, the static scene's predicted motion removed (homography or metric pose
// with the depth of the stereo points around it), and, where depth exists, its 3D position.
#include <cstdint>
#include <span>
#include <vector>

#include <opencv2/core.hpp>

#include "core/geometry/rig.hpp"
#include "core/vision/groups.hpp"

namespace cv {
class DISOpticalFlow;
}

namespace stereod::vision {

enum class GroupFlow : uint8_t {
	Sparse, ///< the temporal matches at the feature points (sub-pixel refined by LK)
	PyrLk,	///< seed 002's pyramidal LK at every grid cell
	Dis	///< DIS dense flow at reduced resolution, averaged per cell
};

struct DenseFlowParams {
	GroupFlow method = GroupFlow::Sparse;
	double scale = 0.5;	    ///< the flow runs on the left image scaled by this
	int step_px = 8;	    ///< grid cell side, full-resolution pixels
	int lk_window = 7;	    ///< seed 002: window 7
	int lk_levels = 3;	    ///< seed 002: three pyramid levels above the original scale
	double lk_min_eigen = 1e-3; ///< seed 002's 0.001: weaker gradients than this carry no motion (zeroed)
	/// A cell's flow followed back (lk: tracked back from where it landed; dis: the backward flow field at
	/// the cell it moved to) must land within this many full-resolution pixels of its start; 0: no check.
	double max_round_trip_px = 1.0;
	/// A strong cell needs this many strong cells among its 8 neighbours (a mover is a region; a lone cell
	/// is noise); 0: no such rule.
	int min_strong_neighbours = 2;
	/// Cells a group needs at least (a person 20 m away at 1024x768 is ~16 cells of 8 px); groups.min_points
	/// still applies when larger.
	int min_cells = 12;
	/// Depth of a cell from the stereo points within this many cells of it (their median); none beyond.
	int depth_radius_cells = 2;
	/// Labels: a feature point on a cell a group holds joins the group when it has a residual of its own of
	/// at least half groups.min_flow_px, however far that is from the group's (join_by_cells).
	bool label_cells = true;
	/// A cell whose gradients run mostly one way (the smaller eigenvalue of its structure tensor under this
	/// share of the larger: an edge, a streak) has a trustworthy flow only across that way (the aperture
	/// problem): CellFlow::across, and a group made mostly of cells that moved only along their edges is
	/// dropped (find_groups). 0: no cell is on an edge.
	double aperture_ratio = 0.15;
};

/// The image the dense flow runs on: the grey left image scaled by params.scale.
cv::Mat dense_flow_image(const cv::Mat &grey, const DenseFlowParams &params);

/// Flow of each grid cell from `prev` to `cur` (both from dense_flow_image), in full-resolution pixels.
/// Cells are row-major over the grid of `full_size` (cols = full_size.width / step_px). `dis` keeps the DIS
/// object between frames (made on first use).
struct CellFlow {
	int cols = 0, rows = 0;
	std::vector<cv::Point2f> flow; ///< per cell, from the previous frame to this one
	std::vector<uint8_t> valid;    ///< the flow was measured (LK converged, or DIS)
	/// With aperture_ratio set: per cell, the unit direction across its edges, or (0, 0) where the cell's
	/// gradients run both ways (its whole flow is measured).
	std::vector<cv::Point2f> across;
};
CellFlow dense_flow(const cv::Mat &prev, const cv::Mat &cur, cv::Size full_size, const DenseFlowParams &params,
		    cv::Ptr<cv::DISOpticalFlow> &dis);

/// Depth per grid cell from sparse 3D points (median z of the points within depth_radius_cells of the cell;
/// NaN where none): the stereo points of a frame spread over the cells around them.
std::vector<float> cell_depths(std::span<const cv::KeyPoint> keypoints, std::span<const cv::Vec3f> xyz, int cols,
			       int rows, const DenseFlowParams &params);

/// What the static scene predicts for a cell: the homography, or the metric pose with the cell's depth.
struct StaticSceneModel {
	std::optional<cv::Matx33d> homography; ///< previous image -> current image
	std::optional<geometry::Pose> curr_from_prev;
	std::optional<geometry::StereoRig> rig;
};

/// The grid's cells as the grouping's points, one per cell (index = row * cols + column): position in this
/// frame, flow, residual (flow minus the static scene's prediction; NaN where the flow was not measured or the
/// model needs a depth the cell lacks), and 3D positions where the cells have depth (prev_depth at the cell's
/// previous position, cur_depth at its new one).
std::vector<MotionPoint> cell_motion(const CellFlow &cells, const DenseFlowParams &params,
				     std::span<const float> prev_depth, std::span<const float> cur_depth,
				     const StaticSceneModel &model);

/// Feature points join the group that holds the cell under them (group_of_point, one entry per point; points
/// already in a group keep theirs). `group_of_cell` is find_groups' group_of_point over cell_motion's cells;
/// the cell under a point is the one its previous position (px - flow) falls in, as the cells are the previous
/// frame's grid. For slow movers a point's own residual is a noisier measure of its motion than the cell's
/// windowed flow, and the cells a group holds already passed its motion rule. A point whose own residual is
/// shorter than `still_px` stands still by its own measure and does not join (a background point beside a
/// mover's edge, onto which the window smears the mover's flow), nor does one without a residual (a point
/// without depth under a moving camera: nothing says it moves).
void join_by_cells(std::span<const MotionPoint> points, std::span<const int> group_of_cell, int cols, int rows,
		   int step_px, double still_px, std::vector<int> &group_of_point);

/// The strong cells with at least `min_neighbours` strong cells among their 8 neighbours.
std::vector<uint32_t> supported_cells(std::span<const uint32_t> strong, int cols, int rows, int min_neighbours);

} // namespace stereod::vision
