#include "daemon/dds/dds_publisher.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include <dds/dds.h>
#include <spdlog/spdlog.h>

#include "core/clock.hpp"
#include "ros2_types.h"

namespace stereod::daemon {
namespace {

constexpr size_t kSlots = 4;
/// Covariance of what was not measured: ROS 2 tools read a huge variance as "do not trust" (robot_localization
/// ignores such inputs); the sim and monocular sources publish their identity pose this way.
constexpr double kUnknownVariance = 1e9;
/// Of a pose stereod did measure: the per-frame error the sim's drift figures imply (docs/geometry.md: ~0.5 %
/// of the distance travelled, a few millimetres a frame), as a standard deviation of 1 cm and 1 degree.
constexpr double kPositionVariance = 1e-4;
constexpr double kAngleVariance = 3e-4;

std::string dds_error(dds_return_t rc)
{
	return dds_strretcode(rc);
}

builtin_interfaces_msg_dds__Time_ stamp_of(int64_t ns)
{
	builtin_interfaces_msg_dds__Time_ t{};
	const int64_t clamped = std::max<int64_t>(ns, 0);
	t.sec = static_cast<int32_t>(clamped / 1'000'000'000);
	t.nanosec = static_cast<uint32_t>(clamped % 1'000'000'000);
	return t;
}

void set_diagonal(double (&covariance)[36], double position, double angle)
{
	std::fill(std::begin(covariance), std::end(covariance), 0.0);
	for (int i = 0; i < 3; ++i) {
		covariance[i * 6 + i] = position;
		covariance[(i + 3) * 6 + i + 3] = angle;
	}
}

char *text(const std::string &s)
{
	return const_cast<char *>(s.c_str()); // Cyclone reads it while writing; it never writes through it
}

dds_entity_t make_writer(dds_entity_t participant, const dds_topic_descriptor_t *type, const std::string &topic,
			 const dds_qos_t *qos)
{
	const dds_entity_t t = dds_create_topic(participant, type, topic.c_str(), nullptr, nullptr);
	if (t < 0)
		throw std::runtime_error("DDS topic " + topic + " (" + type->m_typename + "): " + dds_error(t));
	const dds_entity_t w = dds_create_writer(participant, t, qos, nullptr);
	if (w < 0)
		throw std::runtime_error("DDS writer for " + topic + ": " + dds_error(w));
	return w;
}

} // namespace

PoseQ pose_from_matrix(const std::array<double, 16> &m)
{
	PoseQ p;
	p.t = {m[3], m[7], m[11]};
	const double r00 = m[0], r01 = m[1], r02 = m[2], r10 = m[4], r11 = m[5], r12 = m[6], r20 = m[8], r21 = m[9],
		     r22 = m[10];
	// Shepperd's method: the largest of the four candidates keeps the square root well away from zero.
	const double trace = r00 + r11 + r22;
	double x, y, z, w;
	if (trace > 0) {
		const double s = std::sqrt(trace + 1.0) * 2;
		w = 0.25 * s;
		x = (r21 - r12) / s;
		y = (r02 - r20) / s;
		z = (r10 - r01) / s;
	} else if (r00 > r11 && r00 > r22) {
		const double s = std::sqrt(1.0 + r00 - r11 - r22) * 2;
		w = (r21 - r12) / s;
		x = 0.25 * s;
		y = (r01 + r10) / s;
		z = (r02 + r20) / s;
	} else if (r11 > r22) {
		const double s = std::sqrt(1.0 + r11 - r00 - r22) * 2;
		w = (r02 - r20) / s;
		x = (r01 + r10) / s;
		y = 0.25 * s;
		z = (r12 + r21) / s;
	} else {
		const double s = std::sqrt(1.0 + r22 - r00 - r11) * 2;
		w = (r10 - r01) / s;
		x = (r02 + r20) / s;
		y = (r12 + r21) / s;
		z = 0.25 * s;
	}
	if (w < 0) { // q and -q are the same rotation: the one with w >= 0, so that equal poses compare equal
		x = -x;
		y = -y;
		z = -z;
		w = -w;
	}
	const double n = std::sqrt(x * x + y * y + z * z + w * w);
	p.q = {x / n, y / n, z / n, w / n};
	return p;
}

void pack_point(const LabelledPoint &point, uint8_t *out)
{
	const float nan = std::numeric_limits<float>::quiet_NaN();
	const float xyz[3] = {point.xyz_m ? (*point.xyz_m)[0] : nan, point.xyz_m ? (*point.xyz_m)[1] : nan,
			      point.xyz_m ? (*point.xyz_m)[2] : nan};
	std::memcpy(out, xyz, 12);
	std::memcpy(out + 12, &point.u, 4);
	std::memcpy(out + 16, &point.v, 4);
	out[20] = point.label == PointLabel::Static ? 0 : point.label == PointLabel::Dynamic ? 1 : 2;
	out[21] = out[22] = out[23] = 0;
	const auto track = static_cast<uint32_t>(point.track);
	std::memcpy(out + 24, &track, 4);
}

DdsPublisher::DdsPublisher(const DdsConfig &config) : config_(config), slots_(kSlots)
{
	participant_ = dds_create_participant(static_cast<dds_domainid_t>(config.domain), nullptr, nullptr);
	if (participant_ < 0)
		throw std::runtime_error("DDS: cannot join domain " + std::to_string(config.domain) + ": " +
					 dds_error(participant_) +
					 " (check CYCLONEDDS_URI and that a network interface is up)");
	try {
		dds_qos_t *qos = dds_create_qos();
		if (config.qos == "sensor_data") {
			// rmw_qos_profile_sensor_data: best effort, keep last 5, volatile.
			dds_qset_reliability(qos, DDS_RELIABILITY_BEST_EFFORT, 0);
			dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 5);
		} else {
			// rmw_qos_profile_default: reliable, keep last 10, volatile. A writer with KEEP_LAST history
			// never blocks on a slow reader: the oldest sample is replaced.
			dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
			dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 10);
		}
		dds_qset_durability(qos, DDS_DURABILITY_VOLATILE);
		const std::string base = "rt/stereod/" + config.name + "/";
		try {
			odom_writer_ = make_writer(participant_, &nav_msgs_msg_dds__Odometry__desc, base + "odom", qos);
			groups_writer_ = make_writer(participant_, &vision_msgs_msg_dds__Detection3DArray__desc,
						     base + "groups", qos);
			points_writer_ = make_writer(participant_, &sensor_msgs_msg_dds__PointCloud2__desc,
						     base + "points", qos);
			status_writer_ =
				make_writer(participant_, &stereod_msgs_msg_dds__Status__desc, base + "status", qos);
		} catch (...) {
			dds_delete_qos(qos);
			throw;
		}
		dds_delete_qos(qos);
	} catch (...) {
		dds_delete(participant_);
		throw;
	}
	for (auto &slot : slots_) {
		slot.points.reserve(4096);
		slot.groups.reserve(64);
	}
	for (size_t i = 0; i < kSlots; ++i)
		free_.push_back(i);
	cloud_.reserve(4096 * kPointStep);
	thread_ = std::thread([this] { run(); });
	spdlog::info("DDS: publishing rt/stereod/{}/{{odom,groups,points,status}} on domain {} ({} QoS)", config.name,
		     config.domain, config.qos);
}

DdsPublisher::~DdsPublisher()
{
	{
		std::lock_guard lock(mutex_);
		stopping_ = true;
	}
	wake_.notify_all();
	thread_.join();
	dds_delete(participant_);
}

void DdsPublisher::offer(const FrameResult &result)
{
	size_t slot;
	{
		std::lock_guard lock(mutex_);
		if (stopping_)
			return;
		if (free_.empty()) {
			// DDS is behind: the oldest waiting frame makes room (the newest is what a subscriber wants).
			slot = queued_.front();
			queued_.erase(queued_.begin());
			++stats_.frames_dropped;
		} else {
			slot = free_.back();
			free_.pop_back();
		}
	}
	Frame &f = slots_[slot]; // this thread's until queued
	f.seq = result.seq;
	f.t_capture_ns = result.t_capture_ns;
	f.pose_valid = result.ego && result.ego->valid && *result.ego->valid && result.ego->t_world_curr;
	if (f.pose_valid)
		f.t_world_curr = *result.ego->t_world_curr;
	// The time since the previous frame the pipeline processed (T_prev_curr's interval), whether or not that
	// frame made it onto DDS.
	f.twist_dt_s = last_offered_ns_ >= 0 ? static_cast<double>(result.t_capture_ns - last_offered_ns_) * 1e-9 : 0;
	last_offered_ns_ = result.t_capture_ns;
	f.twist_valid = f.pose_valid && result.ego->t_prev_curr.has_value() && f.twist_dt_s > 0;
	if (f.twist_valid)
		f.t_prev_curr = *result.ego->t_prev_curr;
	f.points.assign(result.points.begin(), result.points.end());
	f.groups.assign(result.groups.begin(), result.groups.end());
	{
		std::lock_guard lock(mutex_);
		queued_.push_back(slot);
		groups_in_view_ = static_cast<uint32_t>(result.groups.size());
	}
	wake_.notify_one();
}

void DdsPublisher::offer_status(const protocol::StatusReport &status)
{
	{
		std::lock_guard lock(mutex_);
		status_ = status;
	}
	wake_.notify_one();
}

DdsPublisher::Stats DdsPublisher::stats() const
{
	std::lock_guard lock(mutex_);
	return stats_;
}

void DdsPublisher::run()
{
	std::unique_lock lock(mutex_);
	for (;;) {
		wake_.wait(lock, [&] { return stopping_ || !queued_.empty() || status_.has_value(); });
		if (status_) {
			const protocol::StatusReport status = std::move(*status_);
			status_.reset();
			const uint32_t groups = groups_in_view_;
			lock.unlock();
			publish_status(status, groups);
			lock.lock();
			continue;
		}
		if (queued_.empty()) {
			if (stopping_)
				return;
			continue;
		}
		const size_t slot = queued_.front();
		queued_.erase(queued_.begin());
		lock.unlock();
		const int64_t start = monotonic_ns();
		publish_frame(slots_[slot]);
		const double ms = static_cast<double>(monotonic_ns() - start) * 1e-6;
		lock.lock();
		free_.push_back(slot);
		++stats_.frames_published;
		stats_.publish_ms_mean += (ms - stats_.publish_ms_mean) / static_cast<double>(stats_.frames_published);
		stats_.publish_ms_max = std::max(stats_.publish_ms_max, ms);
	}
}

void DdsPublisher::publish_frame(const Frame &f)
{
	const auto stamp = stamp_of(f.t_capture_ns);
	uint64_t errors = 0;

	// ---- odom: the camera in the world (the first frame's camera), its velocity in its own frame
	nav_msgs_msg_dds__Odometry_ odom{};
	odom.header.stamp = stamp;
	odom.header.frame_id = text(config_.frame_id);
	odom.child_frame_id = text(config_.child_frame_id);
	odom.pose.pose.orientation.w = 1.0;
	set_diagonal(odom.pose.covariance, kUnknownVariance, kUnknownVariance);
	set_diagonal(odom.twist.covariance, kUnknownVariance, kUnknownVariance);
	if (f.pose_valid) {
		const PoseQ p = pose_from_matrix(f.t_world_curr);
		odom.pose.pose.position = {p.t[0], p.t[1], p.t[2]};
		odom.pose.pose.orientation = {p.q[0], p.q[1], p.q[2], p.q[3]};
		set_diagonal(odom.pose.covariance, kPositionVariance, kAngleVariance);
	}
	const double dt = f.twist_dt_s;
	if (f.twist_valid) {
		// T_prev_curr holds the current camera in the previous one's frame: over dt, the motion of the camera
		// expressed (to first order) in its own frame, as REP-105 asks of the twist.
		const PoseQ d = pose_from_matrix(f.t_prev_curr);
		odom.twist.twist.linear = {d.t[0] / dt, d.t[1] / dt, d.t[2] / dt};
		const double half_angle = std::acos(std::clamp(d.q[3], -1.0, 1.0));
		const double s = std::sin(half_angle);
		const double angle = 2 * half_angle;
		if (s > 1e-12)
			odom.twist.twist.angular = {d.q[0] / s * angle / dt, d.q[1] / s * angle / dt,
						    d.q[2] / s * angle / dt};
		set_diagonal(odom.twist.covariance, kPositionVariance / (dt * dt), kAngleVariance / (dt * dt));
	}
	errors += dds_write(odom_writer_, &odom) < 0;

	// ---- points
	cloud_.resize(f.points.size() * kPointStep);
	for (size_t i = 0; i < f.points.size(); ++i)
		pack_point(f.points[i], cloud_.data() + i * kPointStep);
	static const std::string kX = "x", kY = "y", kZ = "z", kU = "u", kV = "v", kLabel = "label", kTrack = "track";
	// sensor_msgs/PointField datatypes: UINT8 = 2, UINT32 = 6, FLOAT32 = 7.
	sensor_msgs_msg_dds__PointField_ fields[7] = {
		{text(kX), 0, 7, 1},  {text(kY), 4, 7, 1},	{text(kZ), 8, 7, 1},	 {text(kU), 12, 7, 1},
		{text(kV), 16, 7, 1}, {text(kLabel), 20, 2, 1}, {text(kTrack), 24, 6, 1}};
	sensor_msgs_msg_dds__PointCloud2_ cloud{};
	cloud.header.stamp = stamp;
	cloud.header.frame_id = text(config_.child_frame_id);
	cloud.height = 1;
	cloud.width = static_cast<uint32_t>(f.points.size());
	cloud.fields = {7, 7, fields, false};
	cloud.is_bigendian = false;
	cloud.point_step = kPointStep;
	cloud.row_step = kPointStep * cloud.width;
	cloud.data = {static_cast<uint32_t>(cloud_.size()), static_cast<uint32_t>(cloud_.size()), cloud_.data(), false};
	cloud.is_dense =
		std::all_of(f.points.begin(), f.points.end(), [](const auto &p) { return p.xyz_m.has_value(); });
	errors += dds_write(points_writer_, &cloud) < 0;

	// ---- groups: a box where depth placed the group; its class as the hypothesis; the heading as the box's
	// yaw about the camera's y axis (down), since Detection3D has no velocity field (docs/ros2.md)
	std::vector<vision_msgs_msg_dds__Detection3D_> detections;
	std::vector<vision_msgs_msg_dds__ObjectHypothesisWithPose_> hypotheses;
	std::vector<std::string> ids, classes;
	detections.reserve(f.groups.size());
	hypotheses.reserve(f.groups.size());
	ids.reserve(f.groups.size());
	classes.reserve(f.groups.size());
	for (const auto &g : f.groups) {
		if (!g.position_m)
			continue; // no depth, no 3D box (the NDJSON stream still has its pixels)
		ids.push_back(std::to_string(g.id));
		classes.push_back(g.class_name.empty() ? "moving" : g.class_name);
		vision_msgs_msg_dds__ObjectHypothesisWithPose_ h{};
		h.hypothesis.class_id = text(classes.back());
		h.hypothesis.score = 1.0;
		h.pose.pose.position = {(*g.position_m)[0], (*g.position_m)[1], (*g.position_m)[2]};
		h.pose.pose.orientation.w = 1.0;
		set_diagonal(h.pose.covariance, kUnknownVariance, kUnknownVariance);
		hypotheses.push_back(h);
		vision_msgs_msg_dds__Detection3D_ d{};
		d.header.stamp = stamp;
		d.header.frame_id = text(config_.child_frame_id);
		d.results = {1, 1, &hypotheses.back(), false};
		d.bbox.center.position = h.pose.pose.position;
		d.bbox.center.orientation.w = 1.0;
		if (g.heading_rad) {
			d.bbox.center.orientation.y = std::sin(*g.heading_rad / 2);
			d.bbox.center.orientation.w = std::cos(*g.heading_rad / 2);
		}
		if (g.extent_m)
			d.bbox.size = {(*g.extent_m)[0], (*g.extent_m)[1], (*g.extent_m)[2]};
		d.id = text(ids.back());
		detections.push_back(d);
	}
	vision_msgs_msg_dds__Detection3DArray_ array{};
	array.header.stamp = stamp;
	array.header.frame_id = text(config_.child_frame_id);
	array.detections = {static_cast<uint32_t>(detections.size()), static_cast<uint32_t>(detections.size()),
			    detections.data(), false};
	errors += dds_write(groups_writer_, &array) < 0;
	if (errors > 0) {
		std::lock_guard lock(mutex_);
		stats_.write_errors += errors;
	}
}

void DdsPublisher::publish_status(const protocol::StatusReport &s, uint32_t groups_in_view)
{
	stereod_msgs_msg_dds__Status_ m{};
	m.header.stamp = stamp_of(std::chrono::duration_cast<std::chrono::nanoseconds>(
					  std::chrono::system_clock::now().time_since_epoch())
					  .count());
	m.header.frame_id = text(config_.child_frame_id);
	m.name = text(config_.name);
	m.source = text(s.source);
	m.source_state = text(s.source_state);
	m.uptime_s = s.uptime_s;
	m.fps_capture = s.capture_fps;
	m.fps_publish = s.publish_fps;
	m.frames_captured = s.frames_captured;
	m.frames_published = s.frames_published;
	uint64_t drops = 0;
	// Frames lost, whatever the cause; the socket's per-client counters are messages and clients, not frames.
	for (const char *name : {"ring_overflow", "pool_exhausted", "source_gap", "corrupt", "processing_error"})
		if (const auto it = s.drops.find(name); it != s.drops.end())
			drops += it->second;
	m.drops = drops;
	m.latency_p50_ms = s.capture_to_publish.p50_ms;
	m.latency_p99_ms = s.capture_to_publish.p99_ms;
	m.clients = static_cast<uint32_t>(s.clients);
	m.groups_in_view = groups_in_view;
	if (dds_write(status_writer_, &m) < 0) {
		std::lock_guard lock(mutex_);
		++stats_.write_errors;
	}
}

} // namespace stereod::daemon
