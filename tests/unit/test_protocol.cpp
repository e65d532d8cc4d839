#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "core/latency.hpp"
#include "core/protocol.hpp"

using namespace stereod;

TEST(Protocol, FrameMessageCarriesTheDocumentedFields)
{
	FrameResult r;
	r.seq = 42;
	r.t_capture_ns = 1'000'000'000;
	r.t_host_ns = 2'000'000'000;
	r.t_publish_ns = 2'010'000'000;
	r.source = "sim";
	r.status = FrameStatus::Incomplete;
	r.timing = {{"extract", 1.23456}, {"match", 0.5}};
	r.points = {{10.123F, 20.5F, PointLabel::Dynamic, 8.0F, 20.0F, 42, std::array<float, 3>{1.0F, 2.0F, 3.0F}},
		    {1.0F, 2.0F, PointLabel::Static, 1.0F, 2.0F, 0, std::nullopt}};
	const auto j = nlohmann::json::parse(protocol::frame_message(r));
	for (const char *key : {"v", "type", "seq", "t_capture_ns", "t_host_ns", "t_publish_ns", "source", "status",
				"timing_ms", "points", "ego", "groups"})
		EXPECT_TRUE(j.contains(key)) << key;
	EXPECT_EQ(j["v"], protocol::kVersion);
	EXPECT_EQ(j["type"], "frame");
	EXPECT_EQ(j["status"], "incomplete");
	EXPECT_EQ(j["points"][0]["label"], "dynamic");
	EXPECT_EQ(j["points"][0]["u"], 10.12);
	EXPECT_TRUE(j["points"][0].contains("xyz_m"));
	EXPECT_FALSE(j["points"][1].contains("xyz_m")) << "never invented";
	EXPECT_EQ(j["points"][0]["track"], 42);
	EXPECT_FALSE(j["points"][1].contains("track")) << "0 means not followed";
	EXPECT_TRUE(j["ego"].is_null()) << "no stage computed it";
	EXPECT_TRUE(j["groups"].empty());
}

TEST(Protocol, FrameMessageRoundTrips)
{
	FrameResult r;
	r.seq = 7;
	r.source = "video";
	r.points = {{5.5F, 6.25F, PointLabel::Uncertain, 5.0F, 6.0F, 77, std::nullopt}};
	r.ego = EgoMotion{};
	r.ego->homography = std::array<double, 9>{1, 0, 2, 0, 1, 3, 0, 0, 1};
	r.ego->inliers = 99;
	r.ego->homography_refined = false;
	const FrameResult back = protocol::parse_frame_message(nlohmann::json::parse(protocol::frame_message(r)));
	EXPECT_EQ(back.seq, 7U);
	EXPECT_EQ(back.source, "video");
	ASSERT_EQ(back.points.size(), 1U);
	EXPECT_EQ(back.points[0].label, PointLabel::Uncertain);
	EXPECT_FLOAT_EQ(back.points[0].v, 6.25F);
	EXPECT_EQ(back.points[0].track, 77U);
	ASSERT_TRUE(back.ego.has_value());
	EXPECT_EQ(back.ego->inliers, 99);
	ASSERT_TRUE(back.ego->homography.has_value());
	EXPECT_DOUBLE_EQ((*back.ego->homography)[2], 2.0);
	EXPECT_FALSE(back.ego->homography_refined) << "a failed second fit is said, not hidden";
	EXPECT_FALSE(back.ego->valid.has_value()); // monocular: no pose fields at all
}

TEST(Protocol, StereoPoseAndDepthRoundTrip)
{
	FrameResult r;
	r.points = {{5.5F, 6.25F, PointLabel::Static, 5.0F, 6.0F, 3, std::array<float, 3>{0.25F, -0.5F, 4.125F}}};
	EgoMotion ego;
	ego.valid = true;
	ego.inliers = 321;
	ego.t_prev_curr = std::array<double, 16>{1, 0, 0, 0.01, 0, 1, 0, 0, 0, 0, 1, 0.0466667, 0, 0, 0, 1};
	ego.t_world_curr = ego.t_prev_curr;
	r.ego = ego;
	r.stereo = StereoSummary{900, 612, 700, 7, -0.125F, 250};
	const std::string text = protocol::frame_message(r);
	const auto json = nlohmann::json::parse(text);
	EXPECT_TRUE(json.at("ego").at("homography").is_null());
	EXPECT_FALSE(json.at("ego").contains("reason"));
	EXPECT_EQ(json.at("ego").at("T_prev_curr").size(), 16U);
	const FrameResult back = protocol::parse_frame_message(json);
	ASSERT_TRUE(back.points[0].xyz_m.has_value());
	EXPECT_FLOAT_EQ((*back.points[0].xyz_m)[2], 4.125F);
	ASSERT_TRUE(back.ego && back.ego->valid && back.ego->t_world_curr);
	EXPECT_TRUE(*back.ego->valid);
	EXPECT_NEAR((*back.ego->t_prev_curr)[11], 0.0466667, 1e-9);
	EXPECT_EQ(back.ego->inliers, 321);
	ASSERT_TRUE(back.stereo.has_value());
	EXPECT_EQ(back.stereo->matched, 612);
	EXPECT_FLOAT_EQ(back.stereo->median_row_diff_px, -0.125F);
	EXPECT_EQ(back.stereo->row_search, 250);

	ego.valid = false;
	ego.reason = "only 3 static points with depth (need 15)";
	r.ego = ego;
	const FrameResult lost = protocol::parse_frame_message(nlohmann::json::parse(protocol::frame_message(r)));
	ASSERT_TRUE(lost.ego && lost.ego->valid);
	EXPECT_FALSE(*lost.ego->valid);
	EXPECT_EQ(lost.ego->reason, ego.reason);
}

TEST(Protocol, GroupsRoundTripWithDepthFieldsOnlyWhereMeasured)
{
	FrameResult r;
	TargetGroup image_only;
	image_only.id = 4;
	image_only.box_px = {10.5F, 20, 110, 220.25F};
	image_only.point_count = 17;
	image_only.age_frames = 9;
	image_only.image_velocity_pxps = {-35.5F, 2.25F};
	TargetGroup metric = image_only;
	metric.id = 5;
	metric.missed_frames = 2;
	metric.position_m = std::array<double, 3>{1.5, 0.25, 7.125};
	metric.extent_m = std::array<double, 3>{0.5, 1.75, 0.375};
	metric.velocity_mps = std::array<double, 3>{-1.25, 0, 0.5};
	metric.world_velocity_mps = std::array<double, 3>{-1.5, 0, 0};
	metric.speed_mps = 1.5;
	metric.heading_rad = -1.571;
	metric.velocity_sigma_mps = std::array<double, 2>{0.75, 0.125};
	metric.speed_sigma_mps = 0.25;
	r.groups = {image_only, metric};
	const auto json = nlohmann::json::parse(protocol::frame_message(r));
	EXPECT_FALSE(json.at("groups")[0].contains("position_m")) << "never invented";
	EXPECT_FALSE(json.at("groups")[0].contains("speed_mps"));
	EXPECT_EQ(json.at("groups")[1].at("box_px").size(), 4U);
	const FrameResult back = protocol::parse_frame_message(json);
	ASSERT_EQ(back.groups.size(), 2U);
	EXPECT_EQ(back.groups[0].id, 4);
	EXPECT_EQ(back.groups[0].point_count, 17);
	EXPECT_EQ(back.groups[0].age_frames, 9);
	EXPECT_EQ(back.groups[0].missed_frames, 0);
	EXPECT_EQ(back.groups[1].missed_frames, 2);
	EXPECT_FLOAT_EQ(back.groups[0].box_px[3], 220.3F); // rounded to 0.1 px
	EXPECT_FLOAT_EQ(back.groups[0].image_velocity_pxps[0], -35.5F);
	EXPECT_FALSE(back.groups[0].position_m.has_value());
	ASSERT_TRUE(back.groups[1].position_m && back.groups[1].world_velocity_mps && back.groups[1].heading_rad);
	EXPECT_DOUBLE_EQ((*back.groups[1].position_m)[2], 7.125);
	EXPECT_DOUBLE_EQ((*back.groups[1].extent_m)[1], 1.75);
	EXPECT_DOUBLE_EQ(*back.groups[1].speed_mps, 1.5);
	EXPECT_DOUBLE_EQ(*back.groups[1].heading_rad, -1.571);
	EXPECT_FALSE(json.at("groups")[0].contains("speed_sigma_mps"));
	EXPECT_FALSE(back.groups[0].velocity_sigma_mps.has_value());
	ASSERT_TRUE(back.groups[1].velocity_sigma_mps && back.groups[1].speed_sigma_mps);
	EXPECT_DOUBLE_EQ((*back.groups[1].velocity_sigma_mps)[0], 0.75);
	EXPECT_DOUBLE_EQ((*back.groups[1].velocity_sigma_mps)[1], 0.125);
	EXPECT_DOUBLE_EQ(*back.groups[1].speed_sigma_mps, 0.25);
}

TEST(Protocol, PersonPriorFieldsRoundTripAndAreAbsentWhenOff)
{
	FrameResult off;
	off.points.push_back(LabelledPoint{});
	off.groups.push_back(TargetGroup{});
	const auto plain = nlohmann::json::parse(protocol::frame_message(off));
	EXPECT_FALSE(plain.contains("people"));
	EXPECT_FALSE(plain.at("points")[0].contains("person"));
	EXPECT_FALSE(plain.at("groups")[0].contains("class"));

	FrameResult on = off;
	on.points[0].in_person = true;
	on.groups[0].class_name = "person";
	on.people.push_back({{10, 20.25F, 74, 148}, 2.345F, 3});
	const auto json = nlohmann::json::parse(protocol::frame_message(on));
	EXPECT_EQ(json.at("people")[0].at("age_frames"), 3);
	const FrameResult back = protocol::parse_frame_message(json);
	ASSERT_EQ(back.people.size(), 1U);
	EXPECT_FLOAT_EQ(back.people[0].box_px[1], 20.3F); // rounded to 0.1 px
	EXPECT_FLOAT_EQ(back.people[0].score, 2.35F);
	EXPECT_EQ(back.people[0].age_frames, 3);
	EXPECT_EQ(back.people[0].class_id, -1); // HOG's: no class number written
	EXPECT_FALSE(json.at("people")[0].contains("class_id"));
	EXPECT_FALSE(json.contains("objects"));
	EXPECT_TRUE(back.points[0].in_person);
	EXPECT_EQ(back.groups[0].class_name, "person");
}

TEST(Protocol, AModelsClassesAndPotentiallyDynamicObjectsRoundTrip)
{
	FrameResult r;
	r.people.push_back({{1, 2, 3, 4}, 0.91F, 0, 0});
	r.objects.push_back({{50, 60, 90, 120}, 0.7F, 2, 56});
	const auto json = nlohmann::json::parse(protocol::frame_message(r));
	EXPECT_EQ(json.at("people")[0].at("class_id"), 0);
	EXPECT_EQ(json.at("objects")[0].at("class_id"), 56);
	const FrameResult back = protocol::parse_frame_message(json);
	ASSERT_EQ(back.people.size(), 1U);
	ASSERT_EQ(back.objects.size(), 1U);
	EXPECT_EQ(back.people[0].class_id, 0);
	EXPECT_EQ(back.objects[0].class_id, 56);
	EXPECT_EQ(back.objects[0].age_frames, 2);
	EXPECT_FLOAT_EQ(back.objects[0].box_px[3], 120);
}

// Found by fuzz_frame_message: nlohmann converts numbers with a static_cast, so "width": 1e24 as an int (or
// 1e300 as a float, -1 as a uint64) was undefined behaviour in any client parsing the stream. Refused now.
TEST(Protocol, NumbersOutOfRangeAreRefusedNotCast)
{
	FrameResult r;
	r.points.push_back(LabelledPoint{});
	const auto good = nlohmann::json::parse(protocol::frame_message(r));
	EXPECT_NO_THROW(protocol::parse_frame_message(good));
	for (const auto &[key, value] : {std::pair{"width", nlohmann::json(1e24)}, std::pair{"seq", nlohmann::json(-1)},
					 std::pair{"t_capture_ns", nlohmann::json(1e30)}}) {
		auto bad = good;
		bad[key] = value;
		EXPECT_THROW(protocol::parse_frame_message(bad), std::runtime_error) << key;
	}
	auto far = good;
	far["points"][0]["u"] = 1e300;
	EXPECT_THROW(protocol::parse_frame_message(far), std::runtime_error);
}

TEST(Protocol, RejectsOtherVersions)
{
	auto j = nlohmann::json::parse(protocol::frame_message(FrameResult{}));
	j["v"] = 99;
	EXPECT_THROW(protocol::parse_frame_message(j), std::runtime_error);
}

TEST(Protocol, StatusMessageHasDropsAndPercentiles)
{
	protocol::StatusReport s;
	s.drops = {{"ring_overflow", 3}};
	s.capture_to_publish = summarize_ns({1'000'000, 2'000'000, 3'000'000, 4'000'000});
	const auto j = nlohmann::json::parse(protocol::status_message(s));
	EXPECT_EQ(j["type"], "status");
	EXPECT_EQ(j["drops"]["ring_overflow"], 3);
	EXPECT_DOUBLE_EQ(j["latency_ms"]["capture_to_publish"]["p50"].get<double>(), 2.0);
	EXPECT_DOUBLE_EQ(j["latency_ms"]["capture_to_publish"]["max"].get<double>(), 4.0);
}

TEST(Latency, NearestRankPercentiles)
{
	std::vector<int64_t> samples;
	for (int i = 1; i <= 100; ++i)
		samples.push_back(i * 1'000'000);
	const auto s = summarize_ns(samples);
	EXPECT_DOUBLE_EQ(s.p50_ms, 50.0);
	EXPECT_DOUBLE_EQ(s.p90_ms, 90.0);
	EXPECT_DOUBLE_EQ(s.p99_ms, 99.0);
	EXPECT_EQ(s.samples, 100U);
	LatencyWindow window(10);
	for (int i = 1; i <= 25; ++i)
		window.add(i * 1'000'000);
	EXPECT_EQ(window.summary().samples, 10U);
	EXPECT_DOUBLE_EQ(window.summary().max_ms, 25.0);
}
