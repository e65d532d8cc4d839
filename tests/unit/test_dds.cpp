// The DDS publisher's pure parts (daemon/dds/dds_publisher.hpp) and `[dds]` config. The wire itself is tested
// against an independent subscriber in a network namespace (integration.dds_two_boards).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <thread>

#include "daemon/config.hpp"
#include "daemon/dds/dds_publisher.hpp"

using namespace stereod;
using namespace stereod::daemon;

namespace {

std::array<double, 16> rigid(double yaw, double pitch, double roll, std::array<double, 3> t)
{
	// R = Rz(yaw) Ry(pitch) Rx(roll)
	const double cy = std::cos(yaw), sy = std::sin(yaw), cp = std::cos(pitch), sp = std::sin(pitch),
		     cr = std::cos(roll), sr = std::sin(roll);
	return {cy * cp,
		cy * sp * sr - sy * cr,
		cy * sp * cr + sy * sr,
		t[0],
		sy * cp,
		sy * sp * sr + cy * cr,
		sy * sp * cr - cy * sr,
		t[1],
		-sp,
		cp * sr,
		cp * cr,
		t[2],
		0,
		0,
		0,
		1};
}

/// The rotation matrix of a unit quaternion (x, y, z, w).
std::array<double, 9> matrix_of(const std::array<double, 4> &q)
{
	const double x = q[0], y = q[1], z = q[2], w = q[3];
	return {1 - 2 * (y * y + z * z), 2 * (x * y - z * w),	  2 * (x * z + y * w),
		2 * (x * y + z * w),	 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
		2 * (x * z - y * w),	 2 * (y * z + x * w),	  1 - 2 * (x * x + y * y)};
}

} // namespace

TEST(Dds, PoseFromMatrixGivesTheSameRotationBack)
{
	// Every branch of the conversion: small rotations (trace > 0) and ones near 180 degrees about each axis.
	const std::vector<std::array<double, 3>> angles = {{0, 0, 0},	 {0.1, -0.2, 0.3},  {3.1, 0, 0},
							   {0, 3.1, 0},	 {0, 0, 3.1},	    {-2.5, 1.2, 2.9},
							   {M_PI, 0, 0}, {0.7, -1.5, -2.0}, {1.0, 1.0, 1.0}};
	for (const auto &[yaw, pitch, roll] : angles) {
		const auto m = rigid(yaw, pitch, roll, {1.5, -2.0, 0.25});
		const PoseQ p = pose_from_matrix(m);
		EXPECT_DOUBLE_EQ(p.t[0], 1.5);
		EXPECT_DOUBLE_EQ(p.t[1], -2.0);
		EXPECT_DOUBLE_EQ(p.t[2], 0.25);
		EXPECT_NEAR(std::hypot(std::hypot(p.q[0], p.q[1]), std::hypot(p.q[2], p.q[3])), 1.0, 1e-12);
		EXPECT_GE(p.q[3], 0.0) << "the quaternion with w >= 0";
		const auto r = matrix_of(p.q);
		for (int row = 0; row < 3; ++row)
			for (int col = 0; col < 3; ++col)
				EXPECT_NEAR(r[row * 3 + col], m[row * 4 + col], 1e-12)
					<< "yaw " << yaw << " pitch " << pitch << " roll " << roll;
	}
}

TEST(Dds, PointsArePackedAsTheFieldsSay)
{
	LabelledPoint p;
	p.u = 12.5F;
	p.v = 300.25F;
	p.label = PointLabel::Dynamic;
	p.track = (uint64_t{7} << 32) + 42;
	p.xyz_m = std::array<float, 3>{0.5F, -1.0F, 7.25F};
	uint8_t out[kPointStep];
	pack_point(p, out);
	float f[5];
	std::memcpy(f, out, sizeof(f));
	EXPECT_EQ(f[0], 0.5F);
	EXPECT_EQ(f[1], -1.0F);
	EXPECT_EQ(f[2], 7.25F);
	EXPECT_EQ(f[3], 12.5F);
	EXPECT_EQ(f[4], 300.25F);
	EXPECT_EQ(out[20], 1);
	uint32_t track;
	std::memcpy(&track, out + 24, 4);
	EXPECT_EQ(track, 42U) << "the low 32 bits";

	LabelledPoint no_depth;
	no_depth.label = PointLabel::Uncertain;
	pack_point(no_depth, out);
	std::memcpy(f, out, sizeof(f));
	EXPECT_TRUE(std::isnan(f[0]) && std::isnan(f[1]) && std::isnan(f[2])) << "no depth: NaN, as ROS expects";
	EXPECT_EQ(out[20], 2);
	p.label = PointLabel::Static;
	pack_point(p, out);
	EXPECT_EQ(out[20], 0);
}

TEST(Dds, ConfigRefusesANameRos2CannotUse)
{
	DaemonConfig config;
	EXPECT_NO_THROW(validate(config, "defaults"));
	for (const char *bad : {"front-left", "2cams", "", "a/b", "caf\xc3\xa9"}) {
		config.dds.name = bad;
		try {
			validate(config, "test");
			ADD_FAILURE() << "dds.name '" << bad << "' was accepted";
		} catch (const ConfigError &e) {
			EXPECT_NE(std::string(e.what()).find("dds.name"), std::string::npos) << e.what();
		}
	}
	config.dds.name = "front_left2";
	EXPECT_NO_THROW(validate(config, "test"));
	EXPECT_THROW(apply_override("dds.qos=fast", config), ConfigError);
	EXPECT_THROW(apply_override("dds.domain=233", config), ConfigError);
	apply_override("dds.qos=sensor_data", config);
	apply_override("dds.domain=7", config);
	EXPECT_EQ(config.dds.qos, "sensor_data");
	EXPECT_EQ(config.dds.domain, 7);
}

TEST(DdsPublisher, OffersFromThePipelineNeverWaitAndEveryFrameIsAccounted)
{
	// Confined to the loopback without multicast: a unit test must not announce itself on the host's networks
	// (the wire is tested in a network namespace of its own, integration.dds_two_boards).
	::setenv("CYCLONEDDS_URI",
		 "<General><Interfaces><NetworkInterface "
		 "name=\"lo\"/></Interfaces><AllowMulticast>false</AllowMulticast>"
		 "</General><Discovery><ParticipantIndex>auto</ParticipantIndex><Peers><Peer address=\"localhost\"/>"
		 "</Peers></Discovery>",
		 1);
	DdsConfig config;
	config.enabled = true;
	config.domain = 42;
	config.name = "unit";
	DdsPublisher publisher(config);
	FrameResult r;
	r.points.resize(500);
	for (size_t i = 0; i < r.points.size(); ++i) {
		r.points[i].u = static_cast<float>(i);
		r.points[i].xyz_m = std::array<float, 3>{1, 2, static_cast<float>(i)};
	}
	r.groups.resize(3);
	r.groups[1].position_m = std::array<double, 3>{0, 0, 5};
	r.ego = EgoMotion{};
	r.ego->valid = true;
	r.ego->t_world_curr = std::array<double, 16>{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
	r.ego->t_prev_curr = r.ego->t_world_curr;
	constexpr int kFrames = 300;
	std::thread status([&] {
		protocol::StatusReport s;
		s.source = "sim";
		for (int i = 0; i < 20; ++i) {
			publisher.offer_status(s);
			std::this_thread::sleep_for(std::chrono::milliseconds(1));
		}
	});
	const auto start = std::chrono::steady_clock::now();
	for (int i = 0; i < kFrames; ++i) {
		r.seq = static_cast<uint64_t>(i);
		r.t_capture_ns = 1'000'000'000 + i * 33'333'333LL;
		publisher.offer(r);
	}
	const double offer_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
	status.join();
	for (int i = 0; i < 200; ++i) { // let the publisher's thread catch up
		const auto s = publisher.stats();
		if (s.frames_published + s.frames_dropped == kFrames)
			break;
		std::this_thread::sleep_for(std::chrono::milliseconds(10));
	}
	const auto s = publisher.stats();
	EXPECT_EQ(s.frames_published + s.frames_dropped, static_cast<uint64_t>(kFrames))
		<< "every frame published or counted";
	EXPECT_GT(s.frames_published, 0U);
	EXPECT_EQ(s.write_errors, 0U);
	EXPECT_LT(offer_s, 5.0) << "offering 300 frames took " << offer_s << " s";
}
