#pragma once
// Sparse stereo on rectified images (seed 002 section 3.1): each left keypoint is matched to a right keypoint
// under four constraints, then its disparity is refined to a fraction of a pixel along the row:
//   scale      the two keypoints come from the same or an adjacent pyramid level (size ratio)
//   epipolar   rectified rows agree: |v_left - v_right| <= max_row_diff_px
//   disparity  d = u_left - u_right within [min_disparity_px, max_disparity_px]
//   two-way    the right keypoint's best left match is the same left keypoint (and Lowe's ratio holds)
// Sub-pixel: sum of absolute differences of a window around the left point against the right image at
// integer disparities d0 - r .. d0 + r, the minimum, and the equiangular (V) fit through it and its neighbours.
// The depth is then z = f b / d (geometry/rig.hpp).
// Left keypoints without a right keypoint to match (the right eye's detector missed the corner) are then
// looked for along their row of the right image by correlation (search_row), unless row_search is off.
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "core/geometry/rig.hpp"
#include "core/vision/features.hpp"

namespace stereod::vision {

struct StereoParams {
	bool enabled = true;		 ///< match the right eye when the source is stereo and calibrated
	double max_row_diff_px = 1.0;	 ///< epipolar constraint on rectified rows
	double min_disparity_px = 0.5;	 ///< farther than f b / this is treated as unmeasurable
	double max_disparity_px = 192;	 ///< nearest measurable: f b / this
	double max_size_ratio = 0;	 ///< scale constraint; 0 = one pyramid step of the detector (plus 5 %)
	float ratio = 0.9F;		 ///< Lowe's ratio among the candidates in the band
	int max_distance = 64;		 ///< descriptor distance limit (Hamming bits for ORB)
	int refine_radius_px = 2;	 ///< sub-pixel search around the matched disparity
	int window_radius_px = 5;	 ///< SAD window half-size (11 x 11)
	double disparity_sigma_px = 0.3; ///< disparity noise after refinement, for depth uncertainty
	/// A match whose window's halves (left and right of its centre, or above and below) refine to disparities
	/// more than this apart straddles a depth edge (a mover's outline against the background): the window
	/// holds two surfaces and its disparity follows neither (on Aloe such matches are off by 21 px on average,
	/// the others by 0.43). Such a depth is kept for the labels and the grouping (an outline is where a mover
	/// shows), but a group's velocity is measured without it (StereoDepth::on_edge). 0: no test
	/// (docs/geometry.md, stop 50).
	double edge_split_px = 1.0;
	/// true: a match across a depth edge gets no depth at all. On the sim the labels gain (the walk's strict F1
	/// 0.650 -> 0.783) and the groups lose (`moving_many`'s count exact 0.636 -> 0.400): off by default.
	bool drop_edge_depth = false;
	/// A left keypoint the descriptors leave unmatched (most often the right eye's detector did not fire on
	/// the same corner) is looked for along its rectified row of the right image instead: the window's
	/// normalised correlation at every disparity in range (search_row).
	bool row_search = true;
	/// false (default): the right eye's features are not extracted and every left keypoint is found by the
	/// row search alone. The right eye's detector and descriptors are about two thirds of the stereo stage's
	/// time and add no depth the search does not find; without them the stereo path keeps 30 fps on 2 cores.
	bool right_features = false;
	/// With right_features off, every this many frames (by sequence number) the right eye's features are
	/// matched anyway, so the rig's health is measured by descriptor matches that do not assume the rows
	/// agree: a rig bumped by more than a row leaves the row search nothing to measure. 0 = never.
	int health_every_frames = 30;
	double row_search_min_ncc = 0.9;    ///< correlation the best disparity needs
	double row_search_uniqueness = 0.5; ///< (1 - best) <= this * (1 - best more than 2 px away)
	/// Calibration health: a wider band (this many rows) is searched too, to see how many best matches fall
	/// outside the epipolar band and how far rows disagree.
	double health_band_px = 8.0;
};

/// Per left keypoint: its disparity and 3D point, or NaN where it has none.
struct StereoDepth {
	std::vector<float> disparity;	    ///< pixels, refined; NaN = not matched
	std::vector<cv::Vec3f> xyz;	    ///< left camera, metres; NaN where disparity is
	std::vector<int> right_index;	    ///< matched right keypoint, -1 = none
	std::vector<uint8_t> on_edge;	    ///< 1: the match's window straddles a depth edge (edge_split_px)
	int matched = 0;		    ///< left keypoints with a depth
	int row_searched = 0;		    ///< of those, found by search_row (no right keypoint)
	int candidates = 0;		    ///< left keypoints with any descriptor match inside the health band
	int outside_band = 0;		    ///< of those, best match outside the epipolar band (miscalibration)
	std::vector<float> row_differences; ///< v_left - v_right of the accepted matches (row_offset)
};

/// Matches left to right features (both from extract_features on the rectified images) and measures depth;
/// then the row search for the left keypoints left over. `right` may be empty (right_features off): the row
/// search alone. `left_grey`/`right_grey` are the rectified 8-bit images the keypoints were found in.
StereoDepth match_stereo(const FrameFeatures &left, const FrameFeatures &right, const cv::Mat &left_grey,
			 const cv::Mat &right_grey, const geometry::StereoRig &rig, const StereoParams &params,
			 double detector_scale_step);

/// Sub-pixel disparity at integer pixel (x, y) of the left image near `disparity_px`: the SAD minimum over
/// integer disparities within `radius` and a V fit through its neighbours. NaN when the window leaves an
/// image or the minimum lies on the search edge (the match was wrong by more than the radius).
/// With `split_px` > 0, `straddles` (when given) tells whether the window's halves refine to disparities more
/// than that apart (StereoParams::edge_split_px); the whole window's disparity is returned either way.
float refine_disparity(const cv::Mat &left_grey, const cv::Mat &right_grey, cv::Point2f left_pt, float disparity_px,
		       int radius, int window_radius, double split_px = 0, bool *straddles = nullptr);

/// Disparity of a left point found by searching its row of the right image, for a point without a right
/// keypoint: the zero-mean normalised correlation of the (2 window_radius + 1)^2 window at every integer
/// disparity in [min_disparity_px, max_disparity_px]. Accepted when the best reaches row_search_min_ncc, no
/// disparity more than 2 px away comes near it (row_search_uniqueness), it is not on the range's edge, and
/// the right window searched back along the left row lands within 1 px of the start (two-way); then
/// refine_disparity. NaN otherwise, and for a flat window (correlation of noise).
/// `buffers` are reused from call to call.
struct RowSearchBuffers {
	std::vector<int32_t> cross, column_sum, column_squares;
	std::vector<float> window_sum, window_squares, score;
};
float search_row(const cv::Mat &left_grey, const cv::Mat &right_grey, cv::Point2f left_pt, const StereoParams &params,
		 RowSearchBuffers &buffers, bool *straddles = nullptr);

/// The left-camera 3D point at `left_pt` from search_row, only where it is clean: a disparity in range whose
/// window does not straddle a depth edge, and that triangulates. For points found after the stereo matching
/// (a corner followed into the frame by Lucas-Kanade), whose depth nothing else checks.
std::optional<cv::Vec3f> clean_row_depth(const cv::Mat &left_grey, const cv::Mat &right_grey, cv::Point2f left_pt,
					 const geometry::StereoRig &rig, const StereoParams &params,
					 RowSearchBuffers &buffers);

/// Calibration health: v_left - v_right at a stereo match, to a fraction of a pixel (the SAD minimum over
/// rows -2..2 of the right image at the matched disparity, and a V fit). NaN near the image border.
float row_offset(const cv::Mat &left_grey, const cv::Mat &right_grey, cv::Point2f left_pt, float disparity_px,
		 int window_radius);

/// Calibration health over the stream (no peer reports this live): a running mean of each frame's median row
/// difference of the stereo matches and of the fraction of matches the epipolar band refused. A bumped rig
/// shows as a row difference growing past half a pixel. Once frames with descriptor matches have been seen
/// (right_features, or stereo.health_every_frames), only those count: a bump of more than a row leaves the
/// row search few matches, where the rows happen to look alike (along vertical edges), whose offsets say
/// little.
class CalibrationHealth
{
public:
	/// The mean over the last ~`window` frames (an exponential average after the first `window`).
	explicit CalibrationHealth(int window = 30) : window_(window) {}
	void add(const StereoSummary &frame);
	[[nodiscard]] uint64_t frames() const { return frames_; }
	[[nodiscard]] double row_diff_px() const { return row_diff_px_; }
	[[nodiscard]] double outside_band_fraction() const { return outside_; }
	/// |row difference| beyond the limit (the warning: the rig has drifted out of calibration).
	[[nodiscard]] bool drifted(double limit_px = 0.5) const
	{
		return frames_ >= static_cast<uint64_t>(window_) && std::abs(row_diff_px_) > limit_px;
	}

private:
	int window_;
	uint64_t frames_ = 0;
	bool descriptor_frames_ = false;
	double row_diff_px_ = 0;
	double outside_ = 0;
};

/// Whether the frame with this sequence number matches the right eye's own features: always with
/// right_features, else every health_every_frames frames.
[[nodiscard]] inline bool right_features_wanted(const StereoParams &params, uint64_t sequence)
{
	return params.right_features ||
	       (params.health_every_frames > 0 && sequence % static_cast<uint64_t>(params.health_every_frames) == 0);
}

/// Median of the values (copied); NaN for none.
float median_of(std::vector<float> values);

} // namespace stereod::vision
