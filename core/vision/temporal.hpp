#pragma once
// Motion memory: follows each feature point from frame to frame and keeps a decaying sum of its motion
// relative to the static scene, so a mover too slow to clear the seed's per-frame gate (one walking along the
// line of sight, or one momentarily moving with the camera's pan) is still found once its small motions add
// up. This goes beyond seed 000, which judges every frame pair alone; `window_s = 0` turns it off.
//
// Per point and frame: r = x_n - H x_{n-1} (own motion, pixels). A followed point keeps
//   R = lambda R' + r,  S = lambda S' + 1,  W = lambda^2 W' + 1,  lambda = exp(-dt / window_s)
// so R / S is its recent mean own motion per frame. The gate is |R|^2 / (sigma^2 W) > chi2 (2 dof), with
// sigma the seed's per-frame position noise (classifier.reprojection_sigma_px): each frame's residual is
// taken as independent noise. That is conservative on purpose. A static point's sum mostly telescopes
// (R ~ e_n minus a mean of earlier position errors), but detectors that switch pyramid level or corner
// position give heavy-tailed jumps, and a gate built on the measured typical residual let hundreds of
// static points through on the sim (docs/classification.md has the numbers).
// A point stops being followed (and starts afresh) when its match is not trusted: the texture at both ends
// differs, or r jumps away from the track's mean own motion R / S, which is what a mismatch onto a look-alike
// (a repeated window, say) does. The jump test is its own chi-square test on that 2-d innovation: r carries
// the position noise of both its ends (2 sigma^2 per axis) and R / S that of its frames (2 sigma^2 W / S^2),
// so |r - R/S|^2 / (2 sigma^2 (1 + W / S^2)) > jump_chi2 (2 dof) breaks the track.
#include <cstdint>
#include <limits>
#include <optional>
#include <span>
#include <vector>

#include <opencv2/core.hpp>

#include "core/geometry/rig.hpp"
#include "core/result.hpp"
#include "core/vision/classifier.hpp"
#include "core/vision/groups.hpp"
#include "core/vision/keyframes.hpp"
#include "core/vision/matching.hpp"
#include "core/vision/person_prior.hpp"

namespace stereod::vision {

struct TemporalParams {
	double window_s = 0.5;	 ///< time constant of the memory; 0 turns it off (the seed's per-pair labels only)
	double chi2 = 9.21;	 ///< gate on the remembered own motion (chi-square, 2 dof, 99%)
	double jump_chi2 = 9.21; ///< a frame's own motion this far from the track's mean breaks it (2 dof, 99%)
	int min_age = 3;	 ///< frames a point must have been followed before its memory may label it
};

struct TrackState {
	uint64_t id = 0;	  ///< stable while the point is followed; 0 = none
	cv::Point2f motion{0, 0}; ///< R: decayed sum of own motion, pixels
	float count = 0;	  ///< decayed number of frames summed (R / count: mean own motion per frame)
	float noise_weight = 0;	  ///< W: decayed sum of squared weights, the noise variance of R over sigma^2
	uint32_t age = 0;	  ///< frames followed
	/// Stereo/RGB-D: where the point was in the world when the track's depth was first measured (NaN: not
	/// anchored), that depth's standard deviation, and frames since. A static point stays where it was; a
	/// point walking at the camera, or keeping pace with it, drifts from its anchor by more than one frame's
	/// depth noise can hide (docs/geometry.md, the anchored depth test).
	cv::Vec3f anchor_world{std::numeric_limits<float>::quiet_NaN(), 0, 0};
	float anchor_sigma_m = 0;
	uint32_t anchor_age = 0;
	uint32_t anchor_samples = 0; ///< depths averaged into the anchor (before the test starts)
	/// The last depth measured on this track, in the world, its noise and when: a depth that leaps from it by
	/// more than anything walks starts the anchor again.
	cv::Vec3f last_world{std::numeric_limits<float>::quiet_NaN(), 0, 0};
	float last_sigma_m = 0;
	int64_t last_t_ns = 0;
	/// Frames in a row the pooled drift test (pool_depth_drift) found this track's neighbourhood drifting.
	uint8_t pooled_frames = 0;
};

/// The memory of one frame: a state per keypoint of that frame.
struct TrackSet {
	int64_t t_ns = 0;
	int64_t interval_ns = 0;	       ///< since the frame before; 0 when there was none
	std::optional<cv::Matx33d> homography; ///< the static scene's motion from the frame before to this one
	std::vector<TrackState> by_keypoint;
	uint64_t next_id = 1; ///< ids are handed out in frame order, so a replay gives the same ids
	/// Stereo/RGB-D: this frame's camera in the world (the first frame's camera), carried in frame order
	/// like the rest of the memory; the last estimated motion, to seed the next frame's.
	std::optional<geometry::Pose> world_from_camera;
	std::optional<geometry::Pose> last_motion;
	double last_noise_px = 0; ///< the last pose fit's measured noise (PoseEstimate::residual_sigma_px)
	/// Per keypoint: labelled dynamic, or failing the geometric test, in this frame. Such a point does not vote
	/// for the next frame's pose (seed 001: points found dynamic are left out of tracking), so a mover found
	/// once cannot pull the pose; and a point failing the test again next frame is confirmed dynamic.
	std::vector<uint8_t> dynamic_by_keypoint;
	/// Per keypoint: its position minus where the static scene model put it (the pose and its depth, else the
	/// homography); NaN when there was no prediction. A mover's residual changes little from frame to frame.
	std::vector<cv::Point2f> residual_by_keypoint;
	/// Per keypoint: published dynamic in this frame, by any rule (a group's and the anchored spread's
	/// included). For the output only, like those rules: GroupParams::keep_labels_in_box.
	std::vector<uint8_t> published_dynamic_by_keypoint;
	/// Moving-target groups followed so far (core/vision/groups.hpp).
	GroupMemory groups;
	/// The person prior's regions in this frame (detected here, or carried from the last detection).
	std::vector<PriorRegion> people;
	/// Stereo/RGB-D: the last keyframe (core/vision/keyframes.hpp).
	std::optional<Keyframe> last_keyframe;
};

/// What follow_tracks() needs to know about one match: which keypoints it joins, both ends, and the colours.
struct FollowInput {
	std::span<const Match> matches;		 ///< frame n-1 keypoint -> frame n keypoint
	std::span<const PointPair> pairs;	 ///< the same matches' positions and colours, index for index
	const cv::Matx33d *homography = nullptr; ///< the static scene's motion n-1 -> n; null: no track is followed
	/// Per match, where the static scene model puts it in frame n (stereo: the pose and the point's depth);
	/// when given it replaces the homography, and a NaN prediction leaves that point unfollowed.
	std::span<const cv::Point2f> predicted;
	std::span<const uint8_t> texture_agrees; ///< per match: its two ends look alike (Classification)
	size_t cur_keypoints = 0;		 ///< keypoints in frame n
	int64_t t_ns = 0;			 ///< frame n's capture time
};

/// Frame n's memory from frame n-1's (null: everything starts afresh, as after a gap or on the first frame).
TrackSet follow_tracks(const TrackSet *prev, const FollowInput &input, const ClassifierParams &classifier,
		       const TemporalParams &params);

/// Where each keypoint of the memory's frame should be one frame later, for guided matching: the last frame
/// pair's scene motion carried on (the camera keeps its image velocity over one interval) plus the point's
/// own remembered motion per frame. Nothing when the memory has no homography, or when `next_t_ns` is not
/// about one interval later (frames were lost or the source paused): then there is no basis to predict.
std::optional<std::vector<cv::Point2f>>
predict_positions(const TrackSet &tracks, const std::vector<cv::KeyPoint> &keypoints, int64_t next_t_ns);

/// The jump test's statistic: how far a frame's own motion `own` lies from the track's mean, over its
/// variance (chi-square, 2 dof, for a track whose point keeps its motion).
double jump_statistic(const TrackState &before, cv::Point2f own, const ClassifierParams &classifier);

/// True when a followed point's remembered own motion clears the gate.
bool memory_says_moving(const TrackState &state, const ClassifierParams &classifier, const TemporalParams &params);

/// The anchored depth test's settings (ego.anchor_*, docs/geometry.md).
struct AnchorParams {
	int min_frames = 6;	    ///< the test starts once the anchor is this many frames old
	int max_frames = 90;	    ///< then the track is anchored again (the chained pose drifts slowly)
	double max_speed_mps = 3.0; ///< a depth leaping faster than this since the last one starts the anchor again
	double gate = 6.63;	    ///< chi-square (1 dof) for the leap
	/// The pooled test's drift (AnchorTest::drift_sigmas) is measured once the anchor holds this many depths;
	/// 0 = not measured.
	int pool_samples = 0;
};

/// One frame of the anchored depth test for one track (advance_anchor).
struct AnchorTest {
	/// The anchored test's statistic (chi-square, 1 dof) once the anchor is `min_frames` old; NaN otherwise.
	double statistic = std::numeric_limits<double>::quiet_NaN();
	/// The depth where the anchor (its mean so far, before this frame's depth joins it) puts the point minus
	/// the depth measured, over their joint standard deviation: signed, so that the drifts of a mover's points
	/// add up while a static scene's noise cancels. NaN while the anchor holds fewer than `pool_samples`.
	double drift_sigmas = std::numeric_limits<double>::quiet_NaN();
};

/// The frame's camera in the world both ways, inverted once per frame rather than once per point.
struct CameraInWorld {
	explicit CameraInWorld(const geometry::Pose &world_from_camera_)
		: world_from_camera(world_from_camera_), camera_from_world(world_from_camera_.inverse())
	{
	}
	geometry::Pose world_from_camera;
	geometry::Pose camera_from_world;
};

/// A depth measured on a track in this frame: the point in the camera and its depth's standard deviation.
struct DepthSample {
	cv::Vec3d xyz_camera;
	double sigma_m = 0;
};

/// One frame of the anchored depth test for one track. The anchor starts at the first depth (when
/// `may_start`: not on a point already called dynamic), is the mean of the track's positions in the world
/// until `min_frames` old (so one unlucky measurement does not fail a still point for the next 90 frames),
/// and starts again after `max_frames`, or when the depth leaps from the last one measured by more than
/// `max_speed_mps` allows in the time since (plus both depths' noise at `gate`): a track passing from a
/// mover onto the background behind it. Returns the statistic (anchored_depth_statistic) when the test runs
/// in this frame, and the signed drift for the pooled test.
AnchorTest advance_anchor(TrackState &state, const std::optional<DepthSample> &depth, bool may_start, int64_t t_ns,
			  const CameraInWorld &camera, const AnchorParams &params);

/// Spreading the anchored depth test's finds (ego.anchor_spread_*, docs/geometry.md).
struct DepthSpreadParams {
	double radius_px = 40;	   ///< a point's neighbours are this close in the image; 0 = off
	double depth_ratio = 0.05; ///< and this close in depth, relative to the nearer
	int min_neighbours = 1;	   ///< found neighbours a point needs to become dynamic
};

/// The anchored depth test can only judge a track once it has lived `min_frames`, and the corners on a
/// walker heading at the camera rarely live that long: the walker grows in the image and its corners change.
/// What the test finds on the walker's older tracks speaks for the young ones beside it at the same depth:
/// a point that is `open` (its own track not yet tested) and has depth becomes dynamic when at least
/// `min_neighbours` of the `found` points lie within `radius_px` in the image and within `depth_ratio` of the
/// nearer depth. `px`, `depth_m` (NaN: none), `found` and `open` are per point; returns a flag per point.
std::vector<uint8_t> spread_by_depth(std::span<const cv::Point2f> px, std::span<const float> depth_m,
				     std::span<const uint8_t> found, std::span<const uint8_t> open,
				     const DepthSpreadParams &params);

/// The pooled drift test's settings (ego.anchor_pool_*, docs/geometry.md).
struct DriftPoolParams {
	double radius_px = 80;	   ///< a point's neighbours are this close in the image; 0 = off
	double depth_ratio = 0.05; ///< and this close in depth, relative to the nearer
	int min_points = 4;	   ///< points with a drift in the neighbourhood (the point's own included)
	double sigmas = 3.5;	   ///< the neighbourhood's summed drift over sqrt(its count) must exceed this
	double own_sigmas = 0.5;   ///< and the point's own drift this much, in the same direction
	double hold_sigmas = 2.0;  ///< the gate instead of `sigmas` for a point found in the frames before
};

/// The anchored test judges each track alone, so a walker heading at the camera from 9 m is found only once
/// a single point's depth has drifted past its own noise (about 0.6 m, 20 frames at 1 m/s). The walker's
/// points drift together, while the static scene's noise is independent from point to point: summed over
/// a neighbourhood at one depth, k drifts of d sigmas each make d * sqrt(k) sigmas. A point is found when
/// at least `min_points` points with a drift (`drift_sigmas`, NaN: none) lie within `radius_px` in the image
/// and `depth_ratio` of the nearer depth, their summed drift over sqrt(their count) exceeds `sigmas`, and its
/// own drift has the same sign and at least `own_sigmas` (so the static ground at a walker's feet is not
/// taken along). A point found before (`held`, per point; may be empty) needs only `hold_sigmas`: the sum
/// hovers about the gate while a walker comes on, and a find that flickers makes a group that does. `px`,
/// `depth_m` and `drift_sigmas` are per point; returns a flag per point.
std::vector<uint8_t> pool_depth_drift(std::span<const cv::Point2f> px, std::span<const float> depth_m,
				      std::span<const double> drift_sigmas, std::span<const uint8_t> held,
				      const DriftPoolParams &params);

/// Relabels as dynamic every matched point whose memory says it moves (labels[i] belongs to matches[i]);
/// returns how many changed. Labels the seed already made dynamic stay dynamic. `looser` (per match, may be
/// empty) marks points whose `static` label the memory may overturn at the lower gate `looser_chi2` too: the
/// person prior's `weighted` rule, for points in seed 001's dynamic category.
int promote_remembered_movers(std::span<PointLabel> labels, std::span<const Match> matches, const TrackSet &tracks,
			      const ClassifierParams &classifier, const TemporalParams &params,
			      std::span<const uint8_t> looser = {}, double looser_chi2 = 0);

} // namespace stereod::vision
