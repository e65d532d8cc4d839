#pragma once
// The stereo frame that travels from a capture source through the ring to the workers.
//
// Frames are owned by a FramePool and reused: the images are allocated once, at the geometry the source
// announces, and a source fills them in place. A monocular source fills only `left`; an RGB-D source fills
// `left` (colour) and `depth`. Sources that know the truth (the `sim` scene) fill `truth`.
#include <array>
#include <cstdint>
#include <string_view>

#include <opencv2/core.hpp>

namespace stereod {

enum class PixelFormat : uint8_t {
	Mono8, ///< one 8-bit channel (CV_8UC1)
	Bgr8,  ///< three 8-bit channels, OpenCV's B,G,R order (CV_8UC3)
};

enum class FrameStatus : uint8_t {
	Ok,
	Incomplete, ///< some pixels are missing (lost packets, a short read); the rest is valid
	Corrupt,    ///< the payload cannot be trusted
};

std::string_view to_string(PixelFormat format) noexcept;
std::string_view to_string(FrameStatus status) noexcept;
int cv_type(PixelFormat format) noexcept;

/// What a source produces, announced before the first frame so the pool can be allocated.
struct FrameGeometry {
	int width = 0;
	int height = 0;
	PixelFormat format = PixelFormat::Bgr8;
	bool stereo = false;	///< a right image is produced
	bool depth = false;	///< a depth image (CV_32FC1, metres, 0 = unknown) is produced
	bool truth = false;	///< ground truth is produced (dynamic-object id mask + object states)
	double nominal_fps = 0; ///< 0 when unknown

	friend bool operator==(const FrameGeometry &, const FrameGeometry &) = default;
};

/// State of one moving object in the ground truth, in the left camera's frame at capture time
/// (x right, y down, z forward, metres).
struct ObjectTruth {
	uint16_t id = 0; ///< the value of this object's pixels in FrameTruth::object_ids (1..255)
	std::array<double, 3> position_m{};
	std::array<double, 3> velocity_mps{};
};

/// Ground truth a synthetic source knows exactly. Fixed capacity: filling it never allocates.
struct FrameTruth {
	static constexpr size_t kMaxObjects = 32;
	cv::Mat object_ids; ///< CV_8UC1, 0 = static scene, otherwise ObjectTruth::id of the visible mover
	std::array<double, 12> camera_pose{}; ///< world-from-camera [R|t], row-major 3x4
	std::array<ObjectTruth, kMaxObjects> objects{};
	size_t object_count = 0;
};

struct StereoFrame {
	uint64_t sequence = 0;	///< the source's own frame counter; gaps mean frames lost before us
	int64_t device_ns = 0;	///< the camera's (or recording's) timestamp of the exposure
	int64_t host_ns = 0;	///< CLOCK_MONOTONIC when the frame was complete on the host
	int64_t lr_skew_ns = 0; ///< right exposure minus left exposure, measured where the source can
	FrameStatus status = FrameStatus::Ok;
	uint16_t source_id = 0; ///< index into the pipeline's source list
	cv::Mat left;
	cv::Mat right;	  ///< empty unless FrameGeometry::stereo
	cv::Mat depth;	  ///< empty unless FrameGeometry::depth
	FrameTruth truth; ///< object_ids empty unless FrameGeometry::truth

	/// Allocates every buffer the geometry asks for. Called once per pool slot, never on the capture path.
	void allocate(const FrameGeometry &geometry);
	/// Resets the metadata for reuse; the buffers stay.
	void reset_metadata() noexcept;
	/// Copies everything into `dst`, whose buffers already have this frame's geometry (then nothing is
	/// allocated: a recorder's or a player's slot).
	void copy_to(StereoFrame &dst) const;
};

} // namespace stereod
