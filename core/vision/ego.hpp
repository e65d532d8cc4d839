#pragma once
// Ego-motion from stereo and seed 001's geometric dynamic check (../shared/seeds/001_*.txt, section III.C).
//
//   estimate_pose     static candidates' 3D points at frame n-1 (stereo) and their pixels at frame n ->
//                     the camera's motion, by RANSAC PnP then Levenberg-Marquardt on the inliers
//   geometric_test    per point, with that motion: eq. 1's epipolar distance d1, the position along the
//                     epipolar line, and eqs. 2-4's depth error d2 = Z_predicted - Z_measured
//
// Normalisation (where the seed adds pixels to metres with theta = 0.1): each term is divided by its own
// standard deviation and the squares summed, a chi-square statistic with one degree of freedom per term:
//   d1     sigma^2 = 2 s_px^2                  (the feature position noise at both ends)
//   along  sigma^2 = 2 s_px^2 + (L s_z / Z)^2  (L: how far depth moves the prediction along the line,
//                                               the parallax between the point's projection and the
//                                               projection at infinite depth; s_z/Z its depth's relative noise)
//   d2     sigma^2 = s_z(Z_pred)^2 + s_z(Z_meas)^2, s_z(Z) = Z^2 / (f b) s_d (stereo depth noise)
// A point is moving when the statistic exceeds the chi-square quantile for its degrees of freedom.
// Seed 001 uses d1 and d2 only; the along-line term is what a metric pose adds (a point walking along its
// epipolar line, as a person walking at a camera that walks forward does, changes only that term and d2).
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/geometry/rig.hpp"

namespace stereod::vision {

struct EgoParams {
	bool enabled = true;		  ///< estimate the pose when the source is stereo (or RGB-D) and calibrated
	double ransac_threshold_px = 2.0; ///< PnP RANSAC inlier distance (the first fit's, and the most)
	/// The pose fitted with the inlier distance at this many times the measured noise (residual_sigma_px),
	/// never under `min_ransac_threshold_px` nor over `ransac_threshold_px`; 0 = at `ransac_threshold_px` only.
	/// The noise is the previous frame's, carried by the motion prior; without it, a first fit at
	/// `ransac_threshold_px` measures it and a second fit runs at the distance it gives.
	/// Far points cannot tell a small turn from a sideways step, so only the near static points decide the
	/// translation, by a pixel or two; at a fixed 2 px a mover walking along the optical axis (its image
	/// barely moving) and the near points' noise leave the trade free, and it drifted by 10-20 mm per frame
	/// on the sim's `default` where the clean footage's noise is 0.04 px (docs/geometry.md, The pose).
	double ransac_threshold_sigmas = 3;
	double min_ransac_threshold_px = 0.5;
	int ransac_iterations = 200; ///< P3P samples at most (up to four hypotheses each)
	/// Stop sampling once a sample of all inliers has been drawn with this probability, given the best inlier
	/// fraction so far (the usual adaptive RANSAC bound); 0 draws all `ransac_iterations`.
	double ransac_confidence = 0.999;
	/// RANSAC prefers the hypothesis whose inliers spread over more cells of a coarse image grid (then the
	/// one with more inliers) instead of the one with most inliers.
	bool ransac_spread_score = true;
	int min_inliers = 15;	     ///< fewer: the pose is not trusted (ego.valid = false)
	double max_depth_m = 60;     ///< farther points carry no translation; they still vote for rotation
	double pixel_sigma_px = 1.0; ///< feature position noise for the geometric test (when not measured)
	/// Take the geometric test's pixel noise from each frame's pose fit instead of `pixel_sigma_px`: the
	/// residual of a static point under the pose is exactly what the test measures, so the spread of the
	/// fit's residuals is its noise (from their median, which the movers among the candidates barely move).
	/// A fixed sigma is either loose on clean footage (a walker keeping pace passes) or tight on rough
	/// footage (false alarms); the measured one follows the footage. Never below `min_pixel_sigma_px`.
	bool measured_noise = true;
	/// The local refinement: after chaining, the pose in the world is refined against the anchored static
	/// points in view (their world positions averaged over the first frames of their tracks, up to
	/// anchor_max_frames old), so the chain's error grows per anchor, not per frame
	/// (refine_against_anchors). Needs anchor_min_frames > 0. Off: it lowers the ATE where the camera
	/// stands or sways (the sim's `toward` 4.5 -> 1.3 cm, static_near 0.095 -> 0.040 cm) but not where it
	/// walks (the walk's drift 0.32 -> 0.37 %), and the walk is what a robot does (docs/geometry.md).
	bool anchor_refine = false;
	int anchor_refine_min_points = 30; ///< anchored points the refinement needs within the RANSAC threshold
	/// The share of the correction applied per frame (1 = all): anchors come and go every frame, each with
	/// its own error, so the full correction jitters; a part of it each frame still pulls a slow drift back
	/// (0.1: a lower ATE on five of six sim scenes, the per-frame motion never more than 0.2 mm worse).
	double anchor_refine_gain = 0.1;
	double min_pixel_sigma_px = 0.1; ///< floor of the measured noise, per axis (sub-pixel matching's limit)
	/// With measured noise, the depth terms' disparity noise is measured too (the pose's inliers' predicted
	/// against measured disparity), never below this.
	double min_disparity_sigma_px = 0.05;
	double chi2_quantile = 0.99; ///< the geometric test's false-alarm rate is 1 - this
	bool along_line = true;	     ///< include the along-the-epipolar-line term (seed 001 has d1 and d2 only)
	bool depth_check = true;     ///< include eq. 4's depth term d2 (needs depth at frame n)
	/// A point is labelled dynamic only when the test fails in this many consecutive frames of its track
	/// (until then it is uncertain): a one-frame failure is usually a mismatch or a stereo error at an
	/// occlusion edge, a mover keeps failing. 1 = every frame alone, as the seed.
	int confirm_frames = 2;
	/// ... and the two failures must move alike: the point's own motion (its residual against the static
	/// scene's prediction) may change between the frames by noise plus this fraction of itself (one standard
	/// deviation). A mover's image velocity changes little in a frame; a mismatch onto a look-alike jumps by
	/// as much as it moved. 0 = no such check (any two failures confirm).
	double confirm_motion_change = 0.25;
	/// Combined labels: a point whose parallax (the pose's prediction against the rotation's alone) is under
	/// this keeps seed 000's label: there the translation is poorly determined and the homography better.
	/// Off by default: measured, it cost the walk more than it gained elsewhere (docs/geometry.md).
	double min_parallax_px = 0;
	/// The anchored depth test: a followed point's depth against where its first measured positions (their
	/// mean), carried by the camera's motion since, put it. Tested once the track is this many frames old
	/// (the noise at each end does not grow with time, a walker's drift does); 0 = off. On since stop 28,
	/// when tracks whose depth leaps (anchor_max_speed_mps) started their anchor again: before, a track that
	/// passed from a mover onto the background failed it (docs/geometry.md has the figures).
	int anchor_min_frames = 6;
	int anchor_max_frames = 90; ///< re-anchored after this many (the chained pose drifts slowly)
	/// A track whose depth changes from the last one measured by more than this speed allows in the time
	/// since (plus the two depths' noise at the chi-square gate) is anchored again instead of tested: a track
	/// passing from a mover onto the background behind it leaps by metres. 0 = no such check.
	double anchor_max_speed_mps = 3.0;
	/// The anchored test's finds spread to the young tracks beside them at the same depth (spread_by_depth):
	/// within this many pixels (0 = off), this fraction of the nearer depth, from at least this many. One
	/// find is enough: the test's finds are nearly all right (precision 0.995 on the sim's `toward`), and
	/// what they spread to is the output's label only (docs/geometry.md has the figures for 1 and 2).
	double anchor_spread_px = 40;
	double anchor_spread_depth = 0.05;
	int anchor_spread_min = 1;
	/// The pooled drift test (pool_depth_drift): once a track's anchor holds this many depths (0 = off), its
	/// signed drift is summed with its neighbours' within anchor_pool_px and anchor_spread_depth; at least
	/// anchor_pool_min of them, a sum over sqrt(count) beyond anchor_pool_sigmas, found in two frames in a
	/// row, make a point dynamic (held after that at anchor_pool_hold_sigmas). For the output only, like the
	/// spread. A walker heading at the camera with many points on it is found sooner: on the sim's `toward`,
	/// seed 1, grouped from frame 10 instead of 22 (docs/geometry.md).
	int anchor_pool_samples = 3;
	double anchor_pool_px = 80;
	int anchor_pool_min = 4;
	double anchor_pool_sigmas = 3.5;
	double anchor_pool_hold_sigmas = 2.0; ///< the gate for a track found in the two frames before
	/// Motion prior: the camera keeps its velocity within these accelerations between frames. Only points
	/// the predicted motion explains within what the accelerations allow may vote. Without it a near,
	/// well-textured mover can win RANSAC: far points cannot tell a turn from a sideways step, so "the
	/// camera followed the mover" explains the far scene and the mover together (docs/geometry.md). 0 = off.
	double max_acceleration_mps2 = 10;	    ///< about 1 g: a walking person or a robot braking hard
	double max_angular_acceleration_radps2 = 5; ///< a quick head turn
};

/// The motion the prior predicts for frame n, and how far the truth may be from it.
struct MotionPrior {
	geometry::Pose predicted; ///< curr_from_prev if the camera kept its last motion
	double translation_tolerance_m = 0;
	double rotation_tolerance_rad = 0;
	/// The last fit's measured noise (PoseEstimate::residual_sigma_px), 0 = not known. With it the pose is
	/// fitted once, at EgoParams::ransac_threshold_sigmas times it, instead of twice.
	double noise_px = 0;
	/// The prior for a frame `interval_s` after the previous one, whose motion over `last_interval_s` was
	/// `last_motion` (constant velocity, scaled to the new interval).
	static MotionPrior constant_velocity(const geometry::Pose &last_motion, double last_interval_s,
					     double interval_s, const EgoParams &params);
};

struct PoseEstimate {
	bool valid = false;
	std::string reason;	       ///< why not, when !valid
	geometry::Pose curr_from_prev; ///< x_curr = R x_prev + t
	int candidates = 0;	       ///< points that could vote
	int inliers = 0;
	std::vector<uint8_t> inlier_mask; ///< per input point
	double rms_px = 0;		  ///< re-projection RMS over the inliers
	/// Per-axis noise of a static point's re-projection residual, from the median residual of all candidates
	/// (a 2-d Gaussian's norm has median 1.1774 sigma): the geometric test's noise when it is measured.
	double residual_sigma_px = 0;
	bool prior_used = false; ///< the candidates were gated by the motion prior
	int samples = 0;	 ///< RANSAC samples drawn (EgoParams::ransac_confidence ends it early), every fit
	double threshold_px = 0; ///< the inlier distance of the fit taken
};

/// `prev_xyz` (frame n-1's camera, NaN = no depth) and `cur_px` are index-aligned; `votes[i] == 0` keeps a
/// point out (known movers, the person prior). With a prior, a point votes only if the predicted motion
/// explains it within the prior's tolerance (and the RANSAC threshold); if too few do, all candidates vote.
PoseEstimate estimate_pose(std::span<const cv::Vec3f> prev_xyz, std::span<const cv::Point2f> cur_px,
			   std::span<const uint8_t> votes, const geometry::StereoRig &rig, const EgoParams &params,
			   const MotionPrior *prior = nullptr);

/// The local refinement's outcome (EgoParams::anchor_refine).
struct AnchorRefinement {
	bool applied = false;
	geometry::Pose world_from_camera; ///< refined when applied, else the input
	int points = 0;			  ///< anchored points offered
	int inliers = 0;		  ///< within the RANSAC threshold after the refinement
	double rms_before_px = 0;	  ///< over those inliers, with the chained pose
	double rms_after_px = 0;
};

/// An anchored static point offered to the local refinement.
struct AnchorView {
	cv::Vec3f world; ///< the anchor (TrackState::anchor_world)
	cv::Point2f px;	 ///< where it is seen now
};

/// The camera's pose in the world (`world_from_camera`, chained frame to frame) refined by Levenberg-Marquardt
/// against the anchors within the RANSAC threshold of the chained pose, twice with the inliers re-selected. Kept only
/// when at least `anchor_refine_min_points` stay inliers, their RMS falls, and the correction stays under 5 cm and 1
/// degree (a larger one means the anchors disagree with the chain for another reason than its slow drift, a mover among
/// them); then `anchor_refine_gain` of it is applied.
AnchorRefinement refine_against_anchors(std::span<const AnchorView> anchors, const geometry::Pose &world_from_camera,
					const geometry::StereoRig &rig, const EgoParams &params);

struct GeometricTest {
	int dof = 0;		 ///< terms evaluated: 0 = no test possible
	double d1_px = 0;	 ///< eq. 1: distance from the epipolar line
	double along_px = 0;	 ///< distance from the predicted position along the line
	double d2_m = 0;	 ///< eq. 4: predicted minus measured depth (0 when no depth at frame n)
	double statistic = 0;	 ///< the normalised sum of squares
	bool moving = false;	 ///< statistic above the chi-square gate for `dof`
	cv::Point2f predicted{}; ///< where a static point would be in frame n (NaN when unknown)
};

/// Inputs of the per-point test that stay the same for a whole frame pair.
struct GeometricContext {
	geometry::StereoRig rig;
	geometry::Pose curr_from_prev;
	cv::Matx33d fundamental; ///< from the pose; all zeros when the camera did not translate
	double disparity_sigma_px = 0.3;
	/// Variance, per image axis, of a static point's position against the prediction (both ends' noise).
	double residual_var_px2 = 2.0;
	EgoParams params;
	/// `residual_sigma_px`: the pose fit's measured noise (PoseEstimate), used when params.measured_noise.
	[[nodiscard]] static GeometricContext make(const geometry::StereoRig &rig, const geometry::Pose &curr_from_prev,
						   double disparity_sigma_px, const EgoParams &params,
						   double residual_sigma_px = 0);
};

/// The test for one match: prev pixel (and its 3D point when measured), cur pixel (and its measured depth,
/// NaN when none).
GeometricTest geometric_test(const GeometricContext &context, cv::Point2f prev_px, const cv::Vec3f &prev_xyz,
			     cv::Point2f cur_px, float cur_depth_m);

/// The anchored depth test: `anchor_world` (the point in the world when its track began, its depth noise
/// `anchor_sigma_m`) seen from the current camera (`camera_from_world`) against the depth measured now.
/// The same difference signed and unsquared: the depth where the anchor puts the point minus the depth
/// measured, over their joint standard deviation (+: nearer than the anchor says); NaN when either is missing.
double anchored_depth_drift(const cv::Vec3f &anchor_world, float anchor_sigma_m,
			    const geometry::Pose &camera_from_world, double cur_depth_m, double cur_sigma_m);

/// Returns the normalised squared depth difference (1 degree of freedom); NaN when either depth is missing.
double anchored_depth_statistic(const cv::Vec3f &anchor_world, float anchor_sigma_m,
				const geometry::Pose &camera_from_world, float cur_depth_m, double cur_sigma_m);

/// The disparity noise of one measurement, from the static points the pose explains: each inlier's
/// disparity predicted from its frame n-1 point and the pose against the one measured at frame n (`cur_depth_m`,
/// NaN = none). The median absolute difference over 0.6745 is the difference's sigma, over sqrt 2 one
/// measurement's. 0 when fewer than `min_points` inliers have depth at both frames.
double measured_disparity_sigma(std::span<const cv::Vec3f> prev_xyz, std::span<const float> cur_depth_m,
				std::span<const uint8_t> inlier_mask, const geometry::Pose &curr_from_prev,
				const geometry::StereoRig &rig, size_t min_points);

/// Whether `residual` (a point's own motion this frame, pixels) continues `prev_residual` (its own motion the
/// frame before): |r - r_prev|^2 / (2 var + (change |r|)^2) within the 2-dof chi-square gate at `quantile`,
/// with `var` the per-axis noise of one residual. True when `change` is 0 or `prev_residual` is unknown (NaN):
/// then there is nothing to compare with.
bool continues_motion(cv::Point2f residual, cv::Point2f prev_residual, double residual_var_px2, double change,
		      double quantile);

/// The standard normal quantile (inverse CDF) at probability p, to double precision.
double normal_quantile(double p);

/// The chi-square quantile for 1-3 degrees of freedom at probability p (0.95, 0.99 or 0.999).
double chi2_quantile(int dof, double p);

} // namespace stereod::vision
