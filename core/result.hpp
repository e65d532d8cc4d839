#pragma once
// What processing one frame produces. Every field is filled only by a stage that computed it: an empty
// `points` or a missing `ego` means no stage produced them, never a placeholder.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/frame.hpp"

namespace stereod {

enum class PointLabel : uint8_t {
	Static,
	Dynamic,
	Uncertain, ///< matched, but neither test could decide (the seed's mismatches are reported as this)
};

std::string_view to_string(PointLabel label) noexcept;

struct LabelledPoint {
	float u = 0; ///< pixel column in the left image of this frame
	float v = 0; ///< pixel row
	PointLabel label = PointLabel::Uncertain;
	float prev_u = 0; ///< where the point was matched in the previous frame
	float prev_v = 0;
	uint64_t track = 0; ///< the same number while the point is followed from frame to frame; 0 = unknown
	std::optional<std::array<float, 3>> xyz_m; ///< left-camera coordinates, when depth is known
	bool in_person = false; ///< lies in a region of the person prior (seed 001's dynamic category)
};

/// A region of the person prior (core/vision/person_prior.hpp): where the detector saw a person.
struct PersonRegion {
	std::array<float, 4> box_px{}; ///< u0, v0, u1, v1 in the left image
	float score = 0;	       ///< the detector's margin when it was seen
	int age_frames = 0;	       ///< frames since the detector saw it (0: this frame)
	int class_id = -1;	       ///< the ONNX model's class; -1: HOG's person
};

/// The camera's own motion. Monocular sources have the image homography of the static scene only; stereo
/// and RGB-D sources also have the metric pose (left rectified camera: x right, y down, z forward, metres).
struct EgoMotion {
	std::optional<std::array<double, 9>> homography; ///< maps previous-frame pixels to this frame's, row-major
	int inliers = 0; ///< points the pose (stereo) or else the final homography was fitted to
	int homography_inliers = 0;
	/// False when the seed's second fit (from the refined static set) failed and `homography` is the first,
	/// rougher one.
	bool homography_refined = true;
	/// Stereo/RGB-D: whether the pose below was estimated for this frame; when not, `reason` says why and
	/// T_world_curr carries the last known pose on.
	std::optional<bool> valid;
	std::string reason;
	std::optional<std::array<double, 16>> t_prev_curr;  ///< previous camera from current, row-major 4x4
	std::optional<std::array<double, 16>> t_world_curr; ///< world (the first frame's camera) from current
	/// Stereo/RGB-D: whether this frame is a keyframe (seed 001 eqs. 6-7), and its static co-visibility index
	/// with the last keyframe (eq. 7).
	std::optional<bool> keyframe;
	std::optional<double> covisibility;
};

/// Sparse stereo of one frame, and the calibration's health as the matches show it.
struct StereoSummary {
	int keypoints = 0;	      ///< left keypoints
	int matched = 0;	      ///< with a depth
	int candidates = 0;	      ///< with a descriptor match anywhere in the wide health band
	int outside_band = 0;	      ///< of those, best match off the epipolar band
	float median_row_diff_px = 0; ///< v_left - v_right of the matches, sub-pixel
	int row_search = 0;	      ///< of `matched`, found along the row of the right image (no right keypoint)
};

/// A moving-target group (core/vision/groups.hpp): points moving together against the static scene.
struct TargetGroup {
	int id = 0;		       ///< the same while the group stays in view
	std::array<float, 4> box_px{}; ///< u0, v0, u1, v1 in the left image
	int point_count = 0;
	int age_frames = 0;
	/// 0: found in this frame. More: not found in the last this-many frames and carried on (coasted) from
	/// where it was last seen by its velocities, for at most groups.coast_frames frames, so that a mover
	/// the flow misses for a frame keeps its box and id.
	int missed_frames = 0;
	std::array<float, 2> image_velocity_pxps{}; ///< du, dv: the members' motion in the image
	/// Where depth exists (left camera, metres): median position, 10-90 % extent, velocity relative to the
	/// camera; with a metric pose also in the world (ego-motion removed), its speed and heading
	/// (atan2(x, z) of the world velocity: 0 along the first frame's optical axis, +pi/2 to its right).
	std::optional<std::array<double, 3>> position_m;
	std::optional<std::array<double, 3>> extent_m;
	std::optional<std::array<double, 3>> velocity_mps;
	std::optional<std::array<double, 3>> world_velocity_mps;
	std::optional<double> speed_mps;
	std::optional<double> heading_rad;
	/// One standard deviation of the world velocity's estimate along the line of sight to the group and
	/// across it (each axis normal to it), and of the speed, from the spread of the group's own per-frame
	/// measurements: a young or far group's speed along the sight is the least sure.
	std::optional<std::array<double, 2>> velocity_sigma_mps;
	std::optional<double> speed_sigma_mps;
	/// With the person prior on: "person" when most of the group's points lie in a person region, else
	/// "unknown"; empty (not sent) with the prior off.
	std::string class_name;
};

struct StageTime {
	std::string name;
	double ms = 0;
};

struct FrameResult {
	uint64_t seq = 0;
	int64_t t_capture_ns = 0; ///< device timestamp of the exposure
	int64_t t_host_ns = 0;	  ///< CLOCK_MONOTONIC at arrival on the host
	int64_t t_publish_ns = 0; ///< CLOCK_MONOTONIC when the message left the pipeline
	int64_t lr_skew_ns = 0;
	std::string source;
	FrameStatus status = FrameStatus::Ok;
	int width = 0;
	int height = 0;
	std::vector<StageTime> timing;
	std::vector<LabelledPoint> points;
	std::optional<EgoMotion> ego;
	std::optional<StereoSummary> stereo;
	std::vector<TargetGroup> groups;
	/// The person prior's regions for this frame; empty when it is off (or saw nobody).
	std::vector<PersonRegion> people;
	/// The prior's potentially dynamic category (an ONNX model that knows chairs): same fields as `people`.
	std::vector<PersonRegion> objects;
};

} // namespace stereod
