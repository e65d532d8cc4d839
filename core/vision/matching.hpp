#pragma once
// Frame n-1 to frame n descriptor matching: brute force over all pairs, or guided by a prediction of where each
// point of frame n-1 will be in frame n (the static scene's motion of the frame pair before).
#include <span>
#include <vector>

#include "core/vision/features.hpp"

namespace stereod::vision {

struct MatchParams {
	float ratio = 0.8F;	 ///< Lowe's ratio test on the two nearest neighbours; 1 disables it
	bool cross_check = true; ///< keep a match only if it is also the best match backwards
	int max_distance = 64;	 ///< Hamming bits (ORB); matches farther apart are dropped
	/// Guided matching: a point may only match within this many pixels of its predicted position, so a
	/// look-alike across the image (a repeated window) can neither be matched nor spoil the ratio test.
	/// It bounds how far a mover can move against the scene in one frame interval (64 px at 30 fps is
	/// about 1.9 m/s across the view at 1 m with a 920 px focal length). 0: always brute force.
	float search_radius_px = 64;
	/// Refine each match's position in frame n to a fraction of a pixel by Lucas-Kanade from its position in
	/// frame n-1: keypoints from coarse pyramid levels are located to 1.2^level pixels only, which a metric
	/// pose turns into centimetres of error (docs/geometry.md).
	bool subpixel = true;
	int subpixel_window_px = 11;	 ///< LK window side
	float subpixel_max_shift_px = 2; ///< a refinement moving the point farther is refused (keeps the keypoint)
	/// Matches found again by the image (rescue_matches): ORB re-detects about two thirds of a frame's corners
	/// in the next, but the ratio test and cross check refuse a share of those it does, and each refusal ends
	/// a track (on the sim a track lasted 3.8 frames on average, too short for the tests that need a few).
	bool rescue = true;
	float rescue_radius_px = 1.5; ///< the unmatched keypoint must lie this close to where Lucas-Kanade lands
	float rescue_back_px = 0.5;   ///< and Lucas-Kanade from there back must land this close to the start
	/// Only keypoints with an unmatched one this close to their predicted position are followed at all.
	float rescue_reach_px = 8;
	int rescue_window_px = 9;      ///< LK window side (3 pyramid levels)
	int rescue_max_distance = 256; ///< Hamming bits between the two descriptors (ORB); 256: not looked at
	/// A followed corner (its track at least a frame old) that the detector does not find again is kept where
	/// Lucas-Kanade lands (lost_corners), as a keypoint of this frame with the previous one's descriptor, so
	/// its track goes on. A mover's corners change shape and come back less often than the background's: on
	/// the sim a corner on the approaching mover was re-detected in 75 % of frames against 94 % on static
	/// ground, and two thirds of its ended tracks ended so (docs/groups.md, stops 51 and 52).
	bool follow_lost = true;
	/// Not where a matched keypoint of this frame lies this close: that corner is followed already.
	float follow_lost_clear_px = 2;
	/// follow_unmatched refuses a point whose window, where Lucas-Kanade lands, differs from its window in the
	/// frame before by more than this many times the median difference of the points it followed in the frame (mean
	/// absolute grey difference, OpenCV's Lucas-Kanade error): Lucas-Kanade set off from a wrong prediction settles
	/// in a window that does not look like the corner, and following it back from the corner's own position, as the
	/// back check does, settles there again. 0: no such check.
	float follow_max_error_ratio = 8;
};

struct Match {
	int prev = 0; ///< index into the previous frame's keypoints
	int cur = 0;  ///< index into this frame's keypoints
	float distance = 0;
};

/// Brute-force matching with ratio test and cross check.
std::vector<Match> match_features(const FrameFeatures &prev, const FrameFeatures &cur, const MatchParams &params);

/// The same tests among candidates near the prediction only: keypoint i of `prev` is compared with the
/// keypoints of `cur` within params.search_radius_px of predicted[i] (one prediction per prev keypoint; a
/// non-finite one matches nothing). The cross check runs over the same candidate pairs.
std::vector<Match> match_features_guided(const FrameFeatures &prev, const FrameFeatures &cur,
					 std::span<const cv::Point2f> predicted, const MatchParams &params);

/// The Lucas-Kanade pyramid rescue_matches and refine_matches follow points on: 3 levels of `grey` with their
/// derivatives, bordered for the larger of params.rescue_window_px and params.subpixel_window_px.
std::vector<cv::Mat> lk_pyramid(const cv::Mat &grey, const MatchParams &params);

/// Matches the descriptor tests refused, found again by the image: each keypoint of `prev` left unmatched by
/// `matches` is followed into `cur` by pyramidal Lucas-Kanade (on the frames' `grey_pyramid`, else built here) from
/// `predicted` (its position when empty), checked by following it back (params.rescue_back_px), and joined to the
/// nearest keypoint of `cur` that is unmatched too, within params.rescue_radius_px of where it landed. Binary
/// descriptors must also be within params.rescue_max_distance (float ones have no absolute scale; the two-way check and
/// the radius decide). Each keypoint joins at most once, the closest pairs first. Appends to `matches` and returns how
/// many it added; nothing without both grey images.
int rescue_matches(const FrameFeatures &prev, const FrameFeatures &cur, std::span<const cv::Point2f> predicted,
		   std::vector<Match> &matches, const MatchParams &params);

/// Where a keypoint of `prev` that no match holds went in `cur`, by the image alone.
struct FollowedPoint {
	int prev = 0;	  ///< index into the previous frame's keypoints
	cv::Point2f at{}; ///< where Lucas-Kanade landed in this frame
	/// On an edge, the unit direction across it (Lucas-Kanade measured the motion that way only); else (0, 0).
	cv::Point2f across{};
};

/// The keypoints of `prev` that `matches` leaves out, followed into `cur` by pyramidal Lucas-Kanade as
/// rescue_matches follows them (from `predicted` when given, checked by following back within
/// params.rescue_back_px), with no keypoint of `cur` needed where they land: the descriptors match only about
/// half of a walking person's keypoints into the next frame (their corners change shape; docs/groups.md,
/// stop 46), and the rest are still there to follow. A point whose window is one-sided (the smaller eigenvalue of its
/// structure tensor under `aperture_ratio` of the larger: an edge, a streak) is marked with the direction across it,
/// since Lucas-Kanade slides along an edge and back again; 0: none is. Nothing without both grey images.
/// `wanted`, when not empty (one flag per keypoint of `prev`), limits the following to the flagged keypoints.
std::vector<FollowedPoint> follow_unmatched(const FrameFeatures &prev, const FrameFeatures &cur,
					    std::span<const cv::Point2f> predicted, std::span<const Match> matches,
					    const MatchParams &params, double aperture_ratio,
					    std::span<const uint8_t> wanted = {});

/// Of `followed` (follow_unmatched's points), the corners worth keeping as keypoints of `cur` in their own right
/// (MatchParams::follow_lost): not on an edge (Lucas-Kanade placed those along it only) and with no keypoint of
/// `cur` used by `matches` within `clear_px` of where they landed. In `followed`'s order.
std::vector<FollowedPoint> lost_corners(std::span<const FollowedPoint> followed, const FrameFeatures &cur,
					std::span<const Match> matches, float clear_px);

/// Across which way the window around `at` in `features`' grey image (side params.rescue_window_px) is
/// one-sided: the unit eigenvector of its structure tensor's larger eigenvalue when the smaller is under
/// `ratio` of it (an edge, a streak: the aperture problem), else (0, 0); (0, 0) without the frame's
/// Lucas-Kanade pyramid or with `ratio` 0.
cv::Point2f edge_across(const FrameFeatures &features, cv::Point2f at, const MatchParams &params, double ratio);

/// Sub-pixel positions in `cur.grey` of the points `prev_pts` of `prev.grey`, starting from `cur_pts`
/// (Lucas-Kanade on two pyramid levels, seeded; on the frames' `grey_pyramid`, else built here): a point LK
/// loses, or moves farther than max_shift_px, keeps its start. Returns how many were refined; nothing without
/// both grey images.
int refine_matches(const FrameFeatures &prev, const FrameFeatures &cur, std::span<const cv::Point2f> prev_pts,
		   std::span<cv::Point2f> cur_pts, const MatchParams &params);

} // namespace stereod::vision
