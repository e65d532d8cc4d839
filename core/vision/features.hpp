#pragma once
// Feature extraction: keypoints, descriptors and the colour under each keypoint, computed once per frame
// and reused as "frame n-1" on the next step.
#include <optional>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/result.hpp"
#include "core/vision/person_prior.hpp"
#include "core/vision/surf.hpp"

namespace stereod::vision {

enum class Detector : uint8_t { Orb, Surf };

/// Where ORB's candidate corners are chosen before the grid shares the budget out.
enum class CandidateSelection : uint8_t {
	/// FAST corners ranked within each grid cell, then scored by Harris there: a weakly textured cell (a plain
	/// coat, a walker's smooth photograph) keeps candidates however strong the rest of the image is.
	PerCell,
	/// OpenCV's ORB detector: the strongest candidates over the whole image (per pyramid level), then the grid.
	WholeImage,
};

struct FeatureParams {
	Detector detector = Detector::Orb;
	int max_features = 1000; ///< after bucketing
	int grid_cols = 8;	 ///< the image is cut into grid_cols x grid_rows cells; each keeps its
	int grid_rows = 6;	 ///< strongest max_features / cells points, so points cover the image
	int orb_levels = 4;	 ///< pyramid levels (OpenCV's default 8 costs twice as much for little gain here)
	float orb_scale = 1.2F;
	int orb_fast_threshold = 12;
	/// Candidates per kept point before bucketing: per cell with CandidateSelection::PerCell, over the whole
	/// image with WholeImage, where with few of them a weakly textured region (a plain coat filling a grid cell)
	/// has none left for its cell to keep, however the grid shares the budget.
	int candidates_per_feature = 3;
	CandidateSelection candidate_selection = CandidateSelection::PerCell;
	/// With PerCell: candidates whose Harris response is under this fraction of the frame's strongest (its 99th
	/// percentile, so one outstanding corner does not set it) are dropped (0 keeps all), as goodFeaturesToTrack's
	/// quality level: plain floors do not take a cell's share with the sensor's noise (docs/groups.md, Stop 55).
	float min_corner_quality = 0.01F;
	/// With PerCell: FAST's threshold for a first pass over each level; only cells short of their share of such
	/// corners are searched again at orb_fast_threshold. A speed setting only (FAST's cost grows with the
	/// corners it finds): the candidates are those of one pass at orb_fast_threshold, whatever this is (at or
	/// under orb_fast_threshold: one pass).
	int orb_fast_first_pass_threshold = 25;
	SurfParams surf; ///< when detector is Surf (max_features above still applies)
};

/// Keypoints and what the classifier needs of them later, so the image itself can be released.
struct FrameFeatures {
	std::vector<cv::KeyPoint> keypoints;
	cv::Mat descriptors;		  ///< one row per keypoint
	int norm_type = cv::NORM_HAMMING; ///< how descriptors compare
	std::vector<cv::Vec3f> colours;	  ///< mean B,G,R around each keypoint
	/// Per keypoint: the left-camera 3D point (metres) from stereo or a depth image, NaN where unmeasured;
	/// empty when the frame has no depth at all (monocular, or no calibration).
	std::vector<cv::Vec3f> xyz;
	/// Per keypoint, with stereo: 1 where the match's window straddles a depth edge (StereoDepth::on_edge):
	/// its depth is kept for the pose, the labels and the grouping, but a group's velocity is measured
	/// without it.
	std::vector<uint8_t> depth_on_edge;
	std::optional<StereoSummary> stereo; ///< how the stereo matching went, when it ran
	/// The left image in grey (owned, not a pool buffer), for sub-pixel refinement of the temporal matches.
	cv::Mat grey;
	/// The grey image's Lucas-Kanade pyramid with its derivatives (lk_pyramid, matching.hpp), built in the
	/// extract stage, which runs beside other frames', so the rescue and the sub-pixel step in the serial pair
	/// stage do not build it.
	std::vector<cv::Mat> grey_pyramid;
	/// The right image in grey, with stereo and matching.follow_lost: the pair stage measures the depth of the
	/// corners it keeps by Lucas-Kanade on it (the extract stage made it; the pair stage runs serially).
	cv::Mat right_grey;
	/// The grey left image scaled for the dense flow (dense_motion.hpp), when the groups use it.
	cv::Mat flow_image;
	/// Per cell of the dense flow's grid: the depth from this frame's 3D points (dense_motion.hpp); empty
	/// without depth or dense flow.
	std::vector<float> cell_depth;
	/// The person prior's detections in this frame; nothing when the detector did not run on it.
	std::optional<std::vector<PriorRegion>> people;
};

/// Mean colour (B,G,R; grey images repeat the one channel) of the patch around `at`, clamped to the image.
/// An empty image has no colour: NaN, which fails every texture comparison.
cv::Vec3f sample_colour(const cv::Mat &image, cv::Point2f at, int radius);

/// Keeps at most `max_total` keypoints, spread over a grid: each cell keeps its strongest. With fewer
/// keypoints allowed than cells, the strongest cell winners are kept. Nothing for an empty image.
std::vector<cv::KeyPoint> bucket_keypoints(std::vector<cv::KeyPoint> keypoints, cv::Size image_size, int grid_cols,
					   int grid_rows, int max_total);

/// ORB keypoints chosen cell by cell (CandidateSelection::PerCell): FAST on each pyramid level, each grid cell's
/// `candidates_per_feature` x its share strongest by FAST score, those scored by Harris as OpenCV's ORB scores
/// them, then bucket_keypoints; each kept keypoint gets ORB's intensity-centroid angle, octave and size, ready
/// for cv::ORB::compute. `grey` is 8-bit single channel.
std::vector<cv::KeyPoint> detect_orb_per_cell(const cv::Mat &grey, const FeatureParams &params);

/// Detects, buckets and describes; `image` is BGR or grey. Colours are patch means of radius colour_radius.
/// `grey`, when given, is `image` already converted (it saves the conversion when the caller has it).
FrameFeatures extract_features(const cv::Mat &image, const FeatureParams &params, int colour_radius,
			       const cv::Mat *grey = nullptr);

} // namespace stereod::vision
