#pragma once
// Results on DDS in ROS 2's own wire form (issue 18, docs/ros2.md): per frame nav_msgs/Odometry
// (`rt/stereod/<name>/odom`), vision_msgs/Detection3DArray (`.../groups`) and sensor_msgs/PointCloud2 with a
// label field (`.../points`); every status interval stereod_msgs/Status (`.../status`). Eclipse Cyclone DDS's C
// API with types idlc generates from daemon/dds/ros2_types.idl; the core knows nothing of DDS.
//
// Publishing never blocks the pipeline: offer() copies what the messages need into one of a few preallocated
// slots and returns; a thread of its own converts and writes. With every slot waiting, the oldest waiting
// frame is replaced and counted (`dropped`): a slow or absent subscriber costs frames on DDS, never on the
// socket or in the pipeline.
#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/protocol.hpp"
#include "core/result.hpp"
#include "daemon/config.hpp"

namespace stereod::daemon {

/// The pose of a 4x4 row-major rigid transform as ROS wants it: translation and unit quaternion (x, y, z, w).
struct PoseQ {
	std::array<double, 3> t{};
	std::array<double, 4> q{0, 0, 0, 1};
};
PoseQ pose_from_matrix(const std::array<double, 16> &m);

/// One point of the PointCloud2, as packed (little-endian, 28 bytes): x, y, z (float32, metres; NaN without
/// depth), u, v (float32, pixels), label (uint8: 0 static, 1 dynamic, 2 uncertain), 3 bytes padding, track
/// (uint32, the low 32 bits of the track id).
inline constexpr uint32_t kPointStep = 28;
void pack_point(const LabelledPoint &point, uint8_t *out);

class DdsPublisher
{
public:
	/// Creates the participant, topics and writers. Throws std::runtime_error naming what failed (the domain,
	/// a topic) and Cyclone's reason.
	explicit DdsPublisher(const DdsConfig &config);
	~DdsPublisher();
	DdsPublisher(const DdsPublisher &) = delete;
	DdsPublisher &operator=(const DdsPublisher &) = delete;

	/// The pipeline's publisher thread: copy what the frame's messages need; never waits on DDS.
	void offer(const FrameResult &result);
	/// The status tick: queue a status message.
	void offer_status(const protocol::StatusReport &status);

	struct Stats {
		uint64_t frames_published = 0; ///< frames written to all three topics
		uint64_t frames_dropped = 0;   ///< frames replaced while waiting (DDS slower than the camera)
		uint64_t write_errors = 0;
		double publish_ms_mean = 0; ///< conversion + dds_write of one frame's three messages
		double publish_ms_max = 0;
	};
	[[nodiscard]] Stats stats() const;

private:
	struct Frame {
		uint64_t seq = 0;
		int64_t t_capture_ns = 0;
		bool pose_valid = false;
		std::array<double, 16> t_world_curr{};
		std::array<double, 16> t_prev_curr{};
		bool twist_valid = false;
		double twist_dt_s = 0;
		std::vector<LabelledPoint> points;
		std::vector<TargetGroup> groups;
	};
	void run();
	void publish_frame(const Frame &frame);
	void publish_status(const protocol::StatusReport &status, uint32_t groups_in_view);

	DdsConfig config_;
	int32_t participant_ = 0;
	int32_t odom_writer_ = 0, groups_writer_ = 0, points_writer_ = 0, status_writer_ = 0;

	mutable std::mutex mutex_;
	std::condition_variable wake_;
	std::vector<Frame> slots_;
	std::vector<size_t> free_, queued_;
	std::optional<protocol::StatusReport> status_;
	uint32_t groups_in_view_ = 0;
	bool stopping_ = false;
	int64_t last_offered_ns_ = -1; ///< offer()'s: the previous frame's capture time, for the twist
	std::vector<uint8_t> cloud_;   ///< reused PointCloud2 data
	Stats stats_;
	std::thread thread_;
};

} // namespace stereod::daemon
