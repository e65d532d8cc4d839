#pragma once
// Moving-target groups (seed 002 sections 3.2-3.3): the points whose motion the camera's own motion does not
// explain, split from the rest by the seed's mean-flow thresholds, clustered by Affinity Propagation on the
// seed's 6-d samples, and followed from frame to frame as groups with a stable id, a box, and, where depth
// exists, a 3D position, extent and velocity.
#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include <opencv2/core.hpp>

#include "core/geometry/rig.hpp"
#include "core/result.hpp"
#include "core/vision/affinity.hpp"

namespace stereod::vision {

/// Which points are clustered into groups.
enum class GroupMembers : uint8_t {
	Auto,  ///< Labels where the frame has a metric pose (stereo, RGB-D), else Flow
	Flow,  ///< seed 002's split: residual flow above the frame's mean in u or v (and min_flow_px)
	Labels ///< the points the classifier labelled dynamic (seed 000 / seed 001's tests, confirmed)
};

struct GroupParams {
	bool enabled = true;
	/// Seed 002 splits by the frame's mean residual, which takes every large residual for motion; with a
	/// metric pose the confirmed labels are the better members (on the stereo sim far fewer groups on the
	/// static scene), without one (monocular footage) the labels miss too many movers and the split is
	/// better. docs/groups.md has both measured. Auto chooses per frame.
	GroupMembers members = GroupMembers::Auto;
	/// A point moves strongly when its residual flow (observed minus what the camera's motion predicts)
	/// exceeds the frame's mean in u or in v (seed 002) and is at least this long, pixels per frame.
	double min_flow_px = 1.0;
	/// GroupMembers::Flow, feature points: the floor falls to this many times the frame's residual noise (a
	/// robust standard deviation over all points, most of them the static scene's) where that is less than
	/// min_flow_px, but not under min_flow_floor_px; 0: min_flow_px always. A fixed camera's residuals are
	/// a few hundredths of a pixel (vtest: 0.04) and a slow walker far off moves under a pixel a frame; a
	/// moving camera's parallax keeps the floor at min_flow_px.
	double noise_sigmas = 8;
	double min_flow_floor_px = 0.5;
	/// Normalisation of the 6-d samples: one unit of each is "still the same group".
	double position_scale_px = 40;
	double flow_scale_px = 1.5;
	double disparity_scale_px = 4;
	double octave_scale = 2;
	int max_points = 300; ///< strong points clustered per frame at most (an even subsample beyond)
	int min_points = 5;   ///< smaller clusters are not groups
	/// Clusters whose boxes come this close (pixels) and that move alike are merged; negative: never.
	double merge_gap_px = 8;
	AffinityParams affinity;
	/// Tracks: a group is matched to the nearest predicted group centre within this distance (or half its
	/// box's diagonal if larger), kept unseen this many frames, published from this age on.
	double association_px = 60;
	int max_missed_frames = 3;
	int min_age_frames = 2;
	/// A published group not found in a frame is still published for this many frames (at most
	/// max_missed_frames, and no more frames than it had been published for), moved on by its velocities
	/// and marked with missed_frames; 0: never.
	int coast_frames = 2;
	/// A published group leaving the view sideways through the band along the image's edge where feature
	/// points give out (edge_band_px), fast enough to cross it in this many frames, is remembered and
	/// coasted for up to this many frames (still no more than it had been published for) while at least
	/// half its predicted box is in the image: its points vanish in the band before the mover leaves the
	/// view. 0: as any other group.
	int edge_coast_frames = 15;
	/// The band along the left and right edges: ORB keeps no corner within 31 px of the image's edge (its
	/// patch), and a corner needs a frame more to be matched and confirmed.
	double edge_band_px = 40;
	/// With depth: a published group not found in a frame whose predicted box lies at least half behind a
	/// group found in it that moves otherwise and is nearer (by more than split_same_depth) is remembered,
	/// published on only for coast_frames as any missed group, for up to this many frames instead of
	/// max_missed_frames, and while missed takes only a cluster that moves alike: a walker passing in front of
	/// another hides it for a few tenths of a second, and it should come out under its id, while the one in front
	/// keeps its own. 0: as any other group.
	int occlusion_frames = 30;
	/// Weight of the new measurement in the velocity averages (after a running mean over the track's first
	/// 1 / smoothing frames).
	double smoothing = 0.2;
	double image_smoothing = 0.5; ///< the same for the image velocity (the tracks' prediction)
	/// The metric velocities' component along the line of sight comes from a straight line fitted to the
	/// track's world positions (its members' median) over the last this many seconds, once they span half of
	/// it: a point's depth change from one frame to the next is its disparity noise times Z^2 / (f b), which
	/// at 9 m and 30 fps is metres per second, while the median position over a window averages it down. Across
	/// the line of sight the points' own image motion stays far the better measure. 0: the averages alone
	/// (docs/groups.md, stop 49).
	double velocity_window_s = 0.5;
	/// Until then, a young group's speed along the sight also comes from its members' anchors (where their
	/// tracks were in the world a third of a second or more ago, the anchored depth test's), weighed against
	/// its averaged frame-to-frame measurements by their spreads (docs/groups.md, stop 53).
	bool anchored_velocity = true;
	/// Labels: a point inside a published group's box whose residual agrees with the group's (within the
	/// larger of this and half the group's residual) becomes dynamic. 2 px: a keypoint's position is
	/// quantised to its pyramid level, so a slow walker's own residual is off the group's by a pixel or two
	/// (docs/groups.md, measured on vtest).
	bool label_points = true;
	double label_tolerance_px = 2.0;
	/// Labels: a point published dynamic in the frame before stays dynamic while it lies inside a published
	/// group's box, whatever its motion this frame: a walker's foot stands still for part of each stride, and
	/// is still the walker's (docs/groups.md, stop 46: vtest's walking-label F1 0.857 -> 0.872, the stereo
	/// sim's rigid movers 0.001-0.004 lower).
	bool keep_labels_in_box = true;
	/// Labels: a point whose track is at most this many frames old (1: followed from the frame before only)
	/// that lies within a published group's members' extent (its box without the margin, where points join
	/// a group too: join_groups), at the group's depth where both have one, is dynamic whatever its motion
	/// this frame, when the box shows new corners at least twice as often as the static scene does
	/// (new_corners_of_groups); 0: off. A walker shows new corners every frame as its limbs and folds move,
	/// while the static scene inside its box was mostly followed before it came; one frame's motion cannot
	/// tell its standing foot from the ground beside it. A rigid mover keeps its corners, and a camera
	/// moving through the scene renews the scene's own, so neither passes the test (docs/groups.md, stop 47).
	int new_in_box_frames = 2;
	/// The same for the new corners under the members' extent, down to this share of its height: a walker's
	/// members are what moves with its body (trunk, arms), and its standing leg and foot below them are not;
	/// a person's legs are about as long as the trunk and head are tall. 0: the extent only. It assumes an
	/// upright camera (docs/groups.md, stop 47).
	double new_below_box_share = 1.0;
	/// The same rule for the groups themselves: which members move like their cluster's median, and which
	/// clusters and tracks move alike. For the dense flow's grid cells (member_area_px2 > 0) tighter than
	/// the labels' (at 2 px patches of flow noise under pure rotation join into groups); for feature points
	/// `point_tolerance_px`, the labels' 2 px for the labels' reason (docs/groups.md, stop 44).
	double member_tolerance_px = 1.0;
	double point_tolerance_px = 2.0;
	/// Added around the members' extent to make a group's box. Feature points are corners inside a mover's
	/// outline, so the body reaches beyond them (the default; points join by label_points inside the
	/// members' extent only). The pipeline sets half a cell when the members are the dense flow's grid
	/// cells, whose positions are the cells' centres.
	double box_margin_px = 8;
	/// The pipeline's too: the image area one member stands for (a dense grid's cell, side squared; 0 for
	/// feature points). With it a cluster must cover at least `min_box_fill` of its box: a few scattered
	/// cells of flow noise that clustered together are not a mover, which is a region.
	double member_area_px2 = 0;
	double min_box_fill = 0.1;
	/// With member_area_px2 (grid cells): a cluster is cut into its connected regions, cells at most this
	/// many empty cells apart being connected; negative: not cut.
	int split_gap_cells = 2;
	/// ... except that regions whose median depths agree within this share of the nearer stay one (stereo
	/// and RGB-D); 0: depth is not looked at.
	double split_same_depth = 0.1;
	/// Feature points without depth (no member_area_px2, monocular footage): a cluster is cut into its
	/// connected parts, points at most this many pixels apart in both directions being connected; 0: not cut.
	double split_gap_px = 45;
	/// Feature points (the sparse flow) with depth: clusters that move alike, whose median depths agree
	/// within `split_same_depth`, and whose boxes are at most this far apart (metres at the nearer depth)
	/// are one group. Affinity Propagation's nearest-neighbour messages cut a near mover's points into
	/// pieces a few decimetres apart, and a piece of each then went its own way as a track; 0: not joined.
	/// (The dense flow's cells keep their own reach, the larger piece's longer side.)
	double merge_reach_m = 1.0;
	/// Pieces at one depth (`split_same_depth`) also move alike when their residuals differ as one mover's
	/// pieces do while it comes at the camera or goes from it: its image spreads out from the centre (or
	/// draws in) by Tz / Z of each point's offset a frame, so its feet move down and its eyes hardly at all.
	/// The residuals may then differ by k times the gap between the pieces, |k| up to this a frame (0.03:
	/// a walker closing at 1.5 m/s 1.7 m away at 30 fps); 0: not looked at.
	double merge_looming = 0.03;
	/// The points the clustering placed in no group (in a cluster under min_points, or taken out of theirs
	/// by the member rule) are clustered once more among themselves, at this times the first round's
	/// preference. Those points are the leftovers of several movers scattered over the frame; at the first
	/// round's preference (its farthest pair's, over the whole frame) Affinity Propagation hands most of them
	/// one exemplar and the member rule then keeps only one mover's (docs/groups.md, stop 45: vtest covered
	/// 0.828 -> 0.853); 1: the first round's.
	bool regroup_unplaced = true;
	double regroup_preference_scale = 0.25;
	/// The sparse flow: the previous frame's keypoints that no match holds are followed into this frame by
	/// Lucas-Kanade (follow_unmatched, matching.hpp) and clustered beside the matched ones, where the members
	/// are chosen by the seed's split (GroupMembers::Flow; no label decides them). They are no frame points:
	/// they make groups and move their boxes, nothing else.
	bool follow_unmatched = true;
};

/// One temporally matched point as the grouping sees it.
struct MotionPoint {
	cv::Point2f px;			   ///< in this frame
	cv::Point2f flow;		   ///< observed, this frame minus the previous, pixels
	cv::Point2f residual;		   ///< observed minus the static scene's predicted motion
	int octave = 0;			   ///< pyramid level of its keypoint (the seed's "scale")
	std::optional<cv::Vec3f> xyz;	   ///< this frame's camera, metres
	std::optional<cv::Vec3f> prev_xyz; ///< the previous frame's camera, metres
	/// Either depth came from a stereo window across a depth edge (StereoParams::edge_split_px): good enough to
	/// cluster by, not to measure the group's velocity with.
	bool depth_on_edge = false;
	/// Where the point's track was in the world a while ago (its anchor: the mean of its first depths), and how
	/// long ago that mean lies, seconds: a velocity over that span carries a frame's depth noise over many
	/// frames instead of one.
	std::optional<cv::Vec3f> anchor_world;
	double anchor_span_s = 0;
	bool dynamic = false; ///< the classifier's label (GroupMembers::Labels)
	/// Where only part of the motion is measured (a grid cell on an edge: the aperture problem), the unit
	/// direction across the edge; (0, 0): the whole residual is measured. find_groups drops a cluster most
	/// of whose members have a residual across their edge under min_flow_px.
	cv::Point2f across{0, 0};
};

/// A track's world positions (its members' median, where depth and the pose exist) at the track's own clock,
/// newest last; a fixed ring so that following a group allocates nothing.
struct PositionHistory {
	static constexpr size_t kCapacity = 64;
	struct Entry {
		double t_s = 0;
		cv::Vec3d world;
		/// The members' median own velocity measured in that frame (world frame), where there was one.
		std::optional<cv::Vec3d> measured_velocity;
	};
	std::array<Entry, kCapacity> entries{};
	size_t size = 0, next = 0;

	void push(const Entry &entry);
	/// The i-th newest (0: the newest); i < size.
	[[nodiscard]] const Entry &newest(size_t i) const;
};

/// A velocity component and the variance of its estimate, (m/s)^2.
struct Estimate {
	double value = 0;
	double variance = 0;
};

/// The velocity along `ray` (a unit vector, the line of sight) over the entries of the last `window_s` before
/// the newest, from two measures weighted by the inverse of their variances: the slope of the least-squares
/// line through the positions (its variance from the line's residuals), and the mean of the measured
/// velocities (its variance from their spread); with the weighted mean's variance, the two taken as fully
/// correlated (they measure the same depths). nullopt when either
/// has fewer than 4 entries, the positions span less than half the window, or a variance is not positive.
std::optional<Estimate> velocity_along(const PositionHistory &history, double window_s, const cv::Vec3d &ray);

/// The variances of the newest `count` (at most) measured velocities of a track: of their component along
/// `ray` (a unit vector), and per axis across it (the mean of the two axes normal to `ray`); the sample
/// variances widened to Student's t over that many (n - 1 degrees of freedom: (n - 1) / (n - 3) times), and
/// their persistence. nullopt with fewer than 4 measurements.
struct MeasuredSpread {
	double along = 0;
	double across = 0;
	/// How many times the variance of an average over them exceeds that of independent measurements, from
	/// their lag-one correlation r along and across: (1 + r) / (1 - r), r taken in [0, 0.7].
	double along_persistence = 1;
	double across_persistence = 1;
};
std::optional<MeasuredSpread> measured_spread(const PositionHistory &history, size_t count, const cv::Vec3d &ray);

/// The trend of the newest `count` (at most) measured velocities of a track: each axis's least-squares slope
/// against time, m/s^2 in the world frame, with the variance of each slope from the line's residuals. An
/// average of velocities lags an accelerating mover by the acceleration times the average's age, an error
/// their spread about their mean does not describe. nullopt with fewer than 4 measurements or all at one
/// time.
struct VelocityTrend {
	cv::Vec3d acceleration;
	cv::Vec3d variance; ///< of each axis's slope, (m/s^2)^2
};
std::optional<VelocityTrend> velocity_trend(const PositionHistory &history, size_t count);

/// A group followed across frames.
struct TrackedGroup {
	int id = 0;
	int age_frames = 0;
	int missed_frames = 0;
	cv::Rect2f box;
	cv::Point2f centre;
	cv::Point2f image_velocity_pxps;
	std::optional<cv::Vec3d> world_velocity_mps;
	std::optional<cv::Vec3d> velocity_mps;
	double clock_s = 0; ///< seconds since the track began, at its last observation
	PositionHistory positions;
	/// As last published (found in a frame and old enough), for coasting; and the members' median residual
	/// then, for the points joining a coasted group.
	std::optional<TargetGroup> published;
	cv::Point2f residual;
};

struct GroupMemory {
	std::vector<TrackedGroup> groups;
	int next_id = 1;
};

/// What the camera did between the frames, for velocities: the interval, and the metric pose when known.
struct GroupMotionContext {
	double dt_s = 0;
	std::optional<geometry::Pose> curr_from_prev;
	std::optional<geometry::Pose> world_from_curr;
	std::optional<geometry::StereoRig> rig; ///< for disparities
	cv::Size image_size;			///< the left image's, for the edge band; empty: unknown
};

struct GroupOutput {
	GroupMemory memory;
	std::vector<TargetGroup> groups;    ///< the published ones
	std::vector<uint32_t> strong;	    ///< indices of the strongly moving points
	std::vector<int> group_of_point;    ///< per point: index into `groups`, or -1
	std::vector<cv::Point2f> residuals; ///< per published group: its members' median residual
	int clusters = 0;		    ///< AP clusters this frame, first round (before the size and age rules)
	int ap_iterations = 0;
	/// Affinity Propagation's time alone, both rounds (the cap is on it); unset when no point moved
	/// strongly enough to be clustered.
	std::optional<double> clustering_ms;
};

/// The seed's split: indices of points whose residual exceeds the mean |u| or mean |v| residual of all of
/// them and is at least `min_flow_px` long. With GroupMembers::Labels: the points labelled dynamic that have
/// a residual. Auto is the pipeline's to resolve per frame (motion_stages); here it splits as Flow.
std::vector<uint32_t> strong_motion(const std::vector<MotionPoint> &points, const GroupParams &params);

/// Points inside a published group's box that move with it join it (group_of_point, which must have one
/// entry per point; points already in a group keep theirs): the point's residual r and the group's g must
/// satisfy |r - g| <= max(label_tolerance_px, |g| / 2) and |r - g| < |r| (nearer the group's motion than the
/// static scene's), with |g| >= min_flow_px. `points` may be other points than the ones clustered (the
/// feature points, when the groups came from the dense flow's cells).
void join_groups(const std::vector<MotionPoint> &points, const GroupOutput &found, const GroupParams &params,
		 std::vector<int> &group_of_point);

/// Whether `at` lies in the group's published box (its edges included).
bool box_holds(const TargetGroup &group, cv::Point2f at);

/// Per published group: whether its box shows new corners (points whose track is at most `young_frames`
/// old) at least twice as often as the static scene does (the points in no box and not `dynamic`), so that a
/// new corner in it is more likely the mover's than the scene's. Boxes with fewer than `min_points` points
/// (at least one): false.
std::vector<uint8_t> boxes_renewing_corners(std::span<const cv::Point2f> at, std::span<const uint32_t> age,
					    std::span<const uint8_t> dynamic, const std::vector<TargetGroup> &groups,
					    uint32_t young_frames, size_t min_points);

/// Labels (GroupParams::new_in_box_frames): per point, whether it is not `dynamic`, new to the tracks (`age`
/// at most new_in_box_frames) and lies on a group whose box renews its corners (boxes_renewing_corners):
/// inside the members' extent (the published box without its `margin_px`) or under it by
/// new_below_box_share of the extent's height, and at the group's depth (within split_same_depth of the
/// nearer) where both have one (`depth_m` NaN: none). `at`, `age`, `depth_m` and `dynamic` hold one entry per
/// point.
std::vector<uint8_t> new_corners_of_groups(std::span<const cv::Point2f> at, std::span<const uint32_t> age,
					   std::span<const float> depth_m, std::span<const uint8_t> dynamic,
					   const std::vector<TargetGroup> &groups, double margin_px,
					   const GroupParams &params);

/// Groups of this frame from its points and the previous frame's memory (null on the first frame).
/// `workspace` keeps Affinity Propagation's buffers between calls.
/// `strong`, when given, replaces strong_motion's choice (the dense flow's cells, thinned to regions).
GroupOutput find_groups(const std::vector<MotionPoint> &points, const GroupMemory *previous,
			const GroupMotionContext &context, const GroupParams &params, AffinityPropagation &workspace,
			const std::vector<uint32_t> *strong = nullptr);

} // namespace stereod::vision
