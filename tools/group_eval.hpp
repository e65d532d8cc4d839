#pragma once
// Scoring moving-target groups (core/vision/groups.hpp) against a synthetic source's truth: how many groups
// against how many movers are in view, which mover each group covers, and how far its position, speed and
// heading are from that mover's; and how often a mover's group id changes. Pure: results and truth in,
// numbers out (issue 16's evaluation; `stereoctl eval --groups`).
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include <nlohmann/json_fwd.hpp>

#include "core/result.hpp"
#include "tools/evaluation.hpp"

namespace stereod::tools {

/// A mover in view in one frame, from the truth: mask pixels, their box, and its state.
struct TrueMover {
	int id = 0;
	int pixels = 0;
	cv::Rect box;
	cv::Vec3d position_m;	      ///< body centre, left camera frame
	cv::Vec3d world_velocity_mps; ///< in the world frame (the first camera's), as groups report it
	/// False for a mover known only by its pixels (a reference without 3D truth, `stereoctl reference`): it
	/// scores counts and coverage, not position, speed, heading or id switches (its ids are per frame).
	bool metric = true;
	/// Whether it walks in this frame (issue 16: "in at least 90 % of the frames where they walk"). A
	/// metric mover walks when its truth says it moves; a pixels-only one as mark_walking() finds.
	bool walking = true;
};

/// One truth.ndjson line's objects that show at least `min_pixels` pixels in `mask` (ids as in the mask).
/// A line without "objects" (a pixels-only reference) makes every mask id with enough pixels a mover.
std::vector<TrueMover> visible_movers(const cv::Mat &mask, const nlohmann::json &truth, int min_pixels);

/// A pixels-only reference (`stereoctl reference`) takes in everyone who differs from the empty scene,
/// people standing still too. A mover in `mask` walks unless the blob that overlaps it most in `before` and
/// in `after` (the reference's masks some frames earlier and later; empty: not there) has moved less than
/// `min_move_px` in both: its box's centre across and its bottom (the feet) down. A mover with no such blob
/// in either walks (it entered, left, or merged: unknown, so it counts). Metric movers are left as they are.
void mark_walking(std::vector<TrueMover> &movers, const cv::Mat &mask, const cv::Mat &before, const cv::Mat &after,
		  double min_move_px);

/// For each group, the mover it covers: the mover id holding the most mask pixels inside the group's box,
/// when that is at least `min_share` of the box; 0 when the box lies mostly on the static scene.
std::vector<int> match_groups(const std::vector<TargetGroup> &groups, const cv::Mat &mask, double min_share = 0.2);

/// True when no two movers' boxes come within `margin_px` of each other: one group each is the right count.
bool movers_separated(const std::vector<TrueMover> &movers, int margin_px);

struct GroupScore {
	uint64_t frames = 0;	       ///< frames scored (with a mask)
	uint64_t frames_separated = 0; ///< with at least one mover in view, all apart
	uint64_t count_exact = 0;      ///< of those, as many groups as movers
	// Why the count is off, in the separated frames: frames with too many or too few groups; mover views
	// with two or more groups on the mover, or none; groups on no mover.
	uint64_t count_over = 0, count_under = 0;
	uint64_t separated_mover_views = 0, separated_movers_split = 0, separated_movers_missed = 0;
	uint64_t separated_groups = 0, separated_groups_off = 0;
	/// Of the separated frames, those in which every mover holds at least `seen_min_points` of the frame's
	/// feature points (any label), and of those the ones with the count exact: the grouping's own count, where
	/// the detector gave every mover something to group. The rest of the separated frames have a mover the
	/// feature points do not see (too plain, too far, not yet in from the edge), which no grouping rule mends.
	uint64_t frames_seen = 0, count_exact_seen = 0;
	/// Per mover of a reference with ids that hold across frames (TrueMover::metric; group_mover_table). In the
	/// separated frames, as above: which mover the count lacks, and in which frames.
	struct MoverCount {
		uint64_t views = 0, missed = 0, split = 0; ///< separated views only
		/// Of the separated views, those with fewer than seen_min_points feature points on the mover, and
		/// how many of the missed ones those are.
		uint64_t unseen = 0, missed_unseen = 0;
		std::vector<uint64_t> missed_frames; ///< seq, in order
		/// Over every view a group covers the mover (separated or not): the relative speed error, and the
		/// frames where the group on it has another id than the one last on it.
		std::vector<double> speed_relative_error;
		std::vector<uint64_t> id_switch_frames;
	};
	std::map<int, MoverCount> by_mover;
	uint64_t frames_without_movers = 0;
	uint64_t groups_without_movers = 0; ///< groups in frames where no mover is in view
	uint64_t groups = 0;
	uint64_t groups_on_movers = 0;
	uint64_t mover_views = 0;    ///< (frame, mover in view) pairs
	uint64_t movers_covered = 0; ///< of those, with a group on the mover
	/// Of the mover views, those with at least `inside_share` of the mover's pixels inside the box of a group
	/// that is on a mover (issue 16's "each walking person inside a group box"): unlike movers_covered, a box
	/// around two people who walk side by side holds both.
	uint64_t movers_inside = 0;
	/// Of the mover views not covered, those no group box touches at all (the rest: a box reaches them but
	/// is another mover's, or holds too little of them).
	uint64_t movers_untouched = 0;
	/// The mover views where the mover walks (TrueMover::walking), and of those the ones covered.
	uint64_t walking_views = 0, walking_covered = 0;
	/// The points' labels against the walking movers (issue 16's "dynamic-label F1 on walking people"): a
	/// point on a walking mover should be dynamic, one off every mask static; points on a mover standing
	/// still, or on a blob too small to be a mover, are not counted (a person standing still is neither).
	LabelScore walking_labels;
	std::vector<double> centroid_error_m;
	std::vector<double> speed_relative_error;
	/// The speed error over the group's published speed_sigma_mps, where it has one: the share within 1 and
	/// 2 says whether the published uncertainty can be trusted (about 0.68 and 0.95 if it is right).
	std::vector<double> speed_error_sigmas;
	std::vector<double> heading_error_deg; ///< movers within max_heading_distance_m, moving
	uint64_t id_switches = 0;
	std::map<int, int> last_group_of_mover; ///< mover id -> group id last seen on it

	/// Scores one frame and carries the id memory on. Frames must come in order.
	void add(const FrameResult &result, const cv::Mat &mask, const std::vector<TrueMover> &movers);
	double max_heading_distance_m = 15.0;
	double min_heading_speed_mps = 0.3;
	int separation_margin_px = 8;
	int seen_min_points = 5; ///< GroupScore::frames_seen: a mover holding fewer is not seen (min_points)
	double inside_share = 0.5;
};

/// The share of `values` under `limit`; NaN when empty (the median is tools::median, evaluation.hpp).
double fraction_below(const std::vector<double> &values, double limit);
std::string group_score_table(const std::string &name, const GroupScore &score);
/// The second table: in the separated frames, how the count goes wrong (too many / too few groups, movers
/// split or missed, groups off every mover).
std::string group_count_table(const std::string &name, const GroupScore &score);
/// The third: the same per mover, with the frames each was missed in as ranges ("3-9, 81").
std::string group_mover_table(const GroupScore &score);

} // namespace stereod::tools
