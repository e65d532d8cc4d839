#include <sstream>

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "tools/evaluation.hpp"
#include "tools/motion_reference.hpp"

using namespace stereod;
using namespace stereod::tools;

TEST(Evaluation, ScoresLabelsAgainstTheMask)
{
	cv::Mat mask = cv::Mat::zeros(100, 100, CV_8UC1);
	mask(cv::Rect(50, 50, 50, 50)).setTo(3); // a mover in the bottom-right quarter
	FrameResult r;
	auto point = [](float u, float v, PointLabel label) {
		return LabelledPoint{u, v, label, u, v, 0, std::nullopt};
	};
	r.points = {point(60, 60, PointLabel::Dynamic),	 point(70, 70, PointLabel::Dynamic), // true dynamic
		    point(10, 10, PointLabel::Dynamic),					     // false dynamic
		    point(80, 80, PointLabel::Static),					     // missed
		    point(20, 20, PointLabel::Static),	 point(30, 30, PointLabel::Static),  // right
		    point(90, 90, PointLabel::Uncertain)};
	const LabelScore s = score_frame(r, mask);
	EXPECT_EQ(s.dynamic_true, 2U);
	EXPECT_EQ(s.dynamic_false, 1U);
	EXPECT_EQ(s.static_false, 1U);
	EXPECT_EQ(s.static_true, 2U);
	EXPECT_EQ(s.uncertain_on_mover, 1U);
	EXPECT_NEAR(s.precision(), 2.0 / 3.0, 1e-12);
	EXPECT_NEAR(s.recall(), 2.0 / 3.0, 1e-12);
	EXPECT_NEAR(s.f1(), 2.0 / 3.0, 1e-12);
	EXPECT_NEAR(s.static_error_rate(), 1.0 / 3.0, 1e-12);
	EXPECT_NEAR(s.mean_coverage(), 0.25, 1e-12);
}

TEST(Evaluation, ListsEachWrongLabelWithItsDistanceToTheOutline)
{
	cv::Mat mask = cv::Mat::zeros(100, 100, CV_8UC1);
	mask(cv::Rect(50, 0, 50, 100)).setTo(2); // a mover on the right half: columns 50-99
	cv::Mat depth = cv::Mat::zeros(100, 100, CV_16UC1);
	depth.setTo(4000);
	FrameResult r;
	LabelledPoint wrong_dynamic{47, 10, PointLabel::Dynamic, 47, 10, 0, std::array<float, 3>{0, 0, 3.5F}};
	LabelledPoint wrong_static{70, 20, PointLabel::Static, 70, 20, 0, std::nullopt};
	LabelledPoint right{20, 20, PointLabel::Static, 20, 20, 0, std::nullopt};
	LabelledPoint unsure{20, 30, PointLabel::Uncertain, 20, 30, 0, std::nullopt};
	r.points = {wrong_dynamic, wrong_static, right, unsure};
	std::ostringstream out;
	write_label_errors(out, 7, r, mask, depth);
	// Column 47 is 3 px from the mover's first column; column 70 is 21 px inside it (to column 49).
	EXPECT_EQ(out.str(), "7,47,10,dynamic,0,3,3.5,4\n7,70,20,static,2,21,,4\n");
	std::ostringstream no_depth;
	write_label_errors(no_depth, 7, r, mask, cv::Mat());
	EXPECT_EQ(no_depth.str(), "7,47,10,dynamic,0,3,3.5,\n7,70,20,static,2,21,,\n");
}

TEST(Evaluation, BorderSkipsPointsOnTheOutline)
{
	cv::Mat mask = cv::Mat::zeros(100, 100, CV_8UC1);
	mask(cv::Rect(50, 0, 50, 100)).setTo(1);
	FrameResult r;
	r.points = {{50.0F, 50.0F, PointLabel::Static, 0, 0, 0, std::nullopt},
		    {80.0F, 50.0F, PointLabel::Dynamic, 0, 0, 0, std::nullopt}};
	EXPECT_EQ(score_frame(r, mask, 0).static_false, 1U);
	const LabelScore bordered = score_frame(r, mask, 3);
	EXPECT_EQ(bordered.static_false, 0U);
	EXPECT_EQ(bordered.dynamic_true, 1U);
}

TEST(Evaluation, CountsLabelsPerMover)
{
	cv::Mat mask = cv::Mat::zeros(100, 100, CV_8UC1);
	mask(cv::Rect(0, 0, 20, 20)).setTo(1);
	mask(cv::Rect(60, 60, 20, 20)).setTo(2);
	FrameResult r;
	auto point = [](float u, float v, PointLabel label) {
		return LabelledPoint{u, v, label, u, v, 0, std::nullopt};
	};
	r.points = {point(5, 5, PointLabel::Dynamic), point(6, 6, PointLabel::Static),
		    point(70, 70, PointLabel::Static), point(71, 71, PointLabel::Uncertain),
		    point(50, 50, PointLabel::Dynamic)}; // the last: scene
	std::map<int, MoverCounts> counts;
	count_per_mover(r, mask, counts);
	count_per_mover(r, mask, counts); // accumulates over frames
	ASSERT_EQ(counts.size(), 2U);
	EXPECT_EQ(counts[1].dynamic, 2U);
	EXPECT_EQ(counts[1].static_, 2U);
	EXPECT_NEAR(counts[1].recall(), 0.5, 1e-12);
	EXPECT_EQ(counts[2].dynamic, 0U);
	EXPECT_EQ(counts[2].static_, 2U);
	EXPECT_EQ(counts[2].uncertain, 2U);
	EXPECT_EQ(counts[2].recall(), 0.0);
}

// ------------------------------------------------------------------------------------------ trajectories
#include <cstdio>
#include <filesystem>

#include "tools/trajectory.hpp"

namespace {

geometry::Pose at(double x, double y, double z, double yaw = 0)
{
	return {geometry::rotation_from_vector({0, yaw, 0}), {x, y, z}};
}

} // namespace

TEST(Trajectory, HandComputedErrors)
{
	// Truth: 1 m steps along z. Estimate: the same, with the third pose 0.3 m off in x.
	const std::vector<geometry::Pose> truth = {at(0, 0, 0), at(0, 0, 1), at(0, 0, 2), at(0, 0, 3)};
	const std::vector<geometry::Pose> estimate = {at(0, 0, 0), at(0, 0, 1), at(0.3, 0, 2), at(0, 0, 3)};
	// RPE over one frame: steps 0->1 exact, 1->2 off by 0.3, 2->3 off by 0.3: RMSE sqrt(2 * 0.09 / 3).
	const RelativeError rpe = relative_pose_error(estimate, truth, 1);
	ASSERT_EQ(rpe.translation_m.count, 3U);
	EXPECT_NEAR(rpe.translation_m.rmse, std::sqrt(0.06), 1e-12);
	EXPECT_NEAR(rpe.translation_m.mean, 0.2, 1e-12);
	EXPECT_NEAR(rpe.translation_m.median, 0.3, 1e-12);
	EXPECT_NEAR(rpe.translation_m.max, 0.3, 1e-12);
	EXPECT_NEAR(rpe.rotation_deg.max, 0, 1e-9);
	// Drift over windows of 2 frames (2 m each): 0->2 off by 0.3 (15 %), 1->3 exact (0 %): mean 7.5 %.
	const Drift d = drift(estimate, truth, 2);
	EXPECT_EQ(d.windows, 2U);
	EXPECT_NEAR(d.translation_percent, 7.5, 1e-9);

	// ATE: an estimate that is the truth moved and turned as a whole has none.
	const geometry::Pose offset{geometry::rotation_from_vector({0.1, 0.7, -0.2}), {5, -2, 1}};
	std::vector<geometry::Pose> moved;
	for (const auto &p : truth)
		moved.push_back(offset * p);
	EXPECT_NEAR(absolute_trajectory_error(moved, truth).translation_m.rmse, 0, 1e-9);
	// Offsets of +0.1, -0.1, -0.1, +0.1 m in x along the line: no rigid motion reduces them (their mean and
	// their trend along z are zero), so every pose is 0.1 m off: RMSE 0.1.
	std::vector<geometry::Pose> wobbly = {offset * at(0.1, 0, 0), offset * at(-0.1, 0, 1), offset * at(-0.1, 0, 2),
					      offset * at(0.1, 0, 3)};
	const AbsoluteError ate = absolute_trajectory_error(wobbly, truth);
	EXPECT_NEAR(ate.translation_m.rmse, 0.1, 1e-9);
	EXPECT_NEAR(ate.translation_m.max, 0.1, 1e-9);

	// Rotation error: a 2-degree yaw step error.
	const std::vector<geometry::Pose> turned = {at(0, 0, 0), at(0, 0, 1, 2 * CV_PI / 180)};
	EXPECT_NEAR(relative_pose_error(turned, {at(0, 0, 0), at(0, 0, 1)}, 1).rotation_deg.max, 2, 1e-9);
}

TEST(Trajectory, TumAndKittiFilesRoundTripAndNameTheBadLine)
{
	const auto dir = std::filesystem::temp_directory_path() / ("stereod-traj-" + std::to_string(::getpid()));
	std::filesystem::create_directories(dir);
	std::vector<StampedPose> poses = {{0.0, at(0, 0, 0)}, {0.05, at(1, 2, 3, 0.3)}};
	write_tum((dir / "a.tum").string(), poses);
	const auto back = read_tum((dir / "a.tum").string());
	ASSERT_EQ(back.size(), 2U);
	EXPECT_NEAR(back[1].t_s, 0.05, 1e-9);
	EXPECT_LT(cv::norm(back[1].pose.t - poses[1].pose.t), 1e-9);
	EXPECT_LT((back[1].pose.inverse() * poses[1].pose).angle(), 1e-8);

	// Associated by time: an estimate 5 ms off still finds its truth, one 50 ms off does not.
	const Association pairs = associate({{0.005, at(0, 0, 0)}, {0.2, at(0, 0, 0)}}, back, 0.02);
	EXPECT_EQ(pairs.estimate.size(), 1U);

	{
		std::FILE *f = std::fopen((dir / "kitti.txt").c_str(), "w");
		std::fputs("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0.5 0 1 0 0 0 0 1 2\n1 0 0 1\n", f);
		std::fclose(f);
	}
	try {
		read_kitti_poses((dir / "kitti.txt").string());
		ADD_FAILURE() << "a short line was accepted";
	} catch (const std::runtime_error &e) {
		EXPECT_NE(std::string(e.what()).find("kitti.txt:3:"), std::string::npos) << e.what();
	}
	std::filesystem::remove_all(dir);
}

// ------------------------------------------------------------------------------------------- groups
#include <nlohmann/json.hpp>

#include "tools/group_eval.hpp"

namespace {

TargetGroup group_at(int id, cv::Rect box, double speed, double heading, std::array<double, 3> position)
{
	TargetGroup g;
	g.id = id;
	g.box_px = {static_cast<float>(box.x), static_cast<float>(box.y), static_cast<float>(box.br().x - 1),
		    static_cast<float>(box.br().y - 1)};
	g.point_count = 20;
	g.speed_mps = speed;
	g.heading_rad = heading;
	g.position_m = position;
	return g;
}

} // namespace

TEST(GroupEvaluation, HandComputedFrames)
{
	// Two movers apart: mover 1 at x 100-139, mover 2 at x 300-339. Truth: the camera is the world
	// (identity pose); mover 1 walks +x at 1.5 m/s (heading 90 deg), mover 2 walks +z at 1 m/s (heading 0).
	cv::Mat mask(240, 480, CV_8UC1, cv::Scalar(0));
	mask(cv::Rect(100, 50, 40, 100)).setTo(1);
	mask(cv::Rect(300, 60, 40, 100)).setTo(2);
	const std::string truth = R"({"seq":1,"camera_pose":[1,0,0,0, 0,1,0,0, 0,0,1,0],"objects":[)"
				  R"({"id":1,"position_m":[-1,0,5],"velocity_mps":[1.5,0,0]},)"
				  R"({"id":2,"position_m":[1,0,6],"velocity_mps":[0,0,1]},)"
				  R"({"id":3,"position_m":[9,0,9],"velocity_mps":[0,0,1]}]})"; // id 3 is not in view
	const auto movers = tools::visible_movers(mask, nlohmann::json::parse(truth), 400);
	ASSERT_EQ(movers.size(), 2U);
	EXPECT_EQ(movers[0].box, cv::Rect(100, 50, 40, 100));
	EXPECT_TRUE(tools::movers_separated(movers, 8));

	tools::GroupScore score;
	FrameResult frame;
	// Frame 1: one group on mover 1, 10% fast, heading 10 deg off, centroid 0.3 m off; one on the background.
	frame.seq = 1;
	frame.groups = {group_at(7, {98, 48, 44, 104}, 1.65, (90 + 10) * CV_PI / 180, {-1, 0, 5.3}),
			group_at(8, {400, 10, 30, 30}, 1.0, 0.0, {3, 0, 8})};
	frame.groups[0].speed_sigma_mps = 0.1; // 0.15 m/s off: 1.5 sigma
	score.add(frame, mask, movers);
	// Frame 2: both movers covered, mover 1 under another id (a switch), speeds exact.
	frame.seq = 2;
	frame.groups = {group_at(9, {100, 50, 40, 100}, 1.5, CV_PI / 2, {-1, 0, 5}),
			group_at(10, {300, 60, 40, 100}, 1.0, 0.0, {1, 0, 6})};
	score.add(frame, mask, movers);

	EXPECT_EQ(score.frames, 2U);
	EXPECT_EQ(score.frames_separated, 2U);
	// Frame 1 has 2 groups for 2 movers, one of them on the background: the count alone does not see that,
	// the `on a mover` share does.
	EXPECT_EQ(score.count_exact, 2U);
	EXPECT_EQ(score.groups, 4U);
	EXPECT_EQ(score.groups_on_movers, 3U);
	EXPECT_EQ(score.mover_views, 4U);
	EXPECT_EQ(score.movers_covered, 3U);
	EXPECT_EQ(score.id_switches, 1U);
	ASSERT_EQ(score.speed_relative_error.size(), 3U);
	EXPECT_NEAR(score.speed_relative_error[0], 0.1, 1e-6);
	ASSERT_EQ(score.speed_error_sigmas.size(), 1U); // the others published no sigma
	EXPECT_NEAR(score.speed_error_sigmas[0], 1.5, 1e-6);
	ASSERT_EQ(score.heading_error_deg.size(), 3U);
	EXPECT_NEAR(score.heading_error_deg[0], 10.0, 1e-4);
	EXPECT_NEAR(score.centroid_error_m[0], 0.3, 1e-6);
	EXPECT_NEAR(tools::fraction_below(score.heading_error_deg, 15), 1.0, 1e-12);

	// Per mover (--count-detail's third table): frames 3-5 and 7 with mover 2 missed, 6 with both found;
	// mover 2's missed frames come out as runs.
	const auto mover_1_only = std::vector<TargetGroup>{group_at(9, {100, 50, 40, 100}, 1.5, CV_PI / 2, {-1, 0, 5})};
	for (const uint64_t seq : {3, 4, 5, 6, 7}) {
		frame.seq = seq;
		if (seq == 6)
			frame.groups.push_back(group_at(10, {300, 60, 40, 100}, 1.0, 0.0, {1, 0, 6}));
		else
			frame.groups = mover_1_only;
		score.add(frame, mask, movers);
	}
	ASSERT_EQ(score.by_mover.size(), 2U);
	EXPECT_EQ(score.by_mover[1].views, 7U);
	EXPECT_EQ(score.by_mover[1].missed, 0U);
	EXPECT_EQ(score.by_mover[2].missed, 5U);
	EXPECT_EQ(score.by_mover[2].missed_frames, (std::vector<uint64_t>{1, 3, 4, 5, 7}));
	// Mover 1's group changed its id in frame 2 (7 -> 9), and its speed was 10 % fast in frame 1, exact in its
	// six frames after.
	EXPECT_EQ(score.by_mover[1].id_switch_frames, (std::vector<uint64_t>{2}));
	EXPECT_NE(tools::group_mover_table(score).find("| 1 (2) |"), std::string::npos)
		<< tools::group_mover_table(score);
	ASSERT_EQ(score.by_mover[1].speed_relative_error.size(), 7U);
	EXPECT_NEAR(score.by_mover[1].speed_relative_error[0], 0.1, 1e-6);
	// No frame so far had a feature point: every view is one of a mover the points do not see.
	EXPECT_EQ(score.frames_seen, 0U);
	EXPECT_NE(tools::group_mover_table(score).find("| 2 | 7 | 7 | 5 | 5 | 0 | 0 | 1, 3-5, 7 | 0 |"),
		  std::string::npos)
		<< tools::group_mover_table(score);

	// The grouping's own count: frame 8 has 5 points on each mover (labels do not matter) and both groups;
	// frame 9 has 4 on mover 2, which is missed there, so the frame is not one where every mover is seen.
	const auto points_on = [](cv::Rect box, int n) {
		std::vector<LabelledPoint> points;
		for (int i = 0; i < n; ++i) {
			LabelledPoint point;
			point.u = static_cast<float>(box.x + 2 + 3 * i);
			point.v = static_cast<float>(box.y + 10);
			point.label = i % 2 == 0 ? PointLabel::Dynamic : PointLabel::Uncertain;
			points.push_back(point);
		}
		return points;
	};
	frame.seq = 8;
	frame.points = points_on({100, 50, 40, 100}, 5);
	for (const auto &point : points_on({300, 60, 40, 100}, 5))
		frame.points.push_back(point);
	frame.groups = mover_1_only;
	frame.groups.push_back(group_at(10, {300, 60, 40, 100}, 1.0, 0.0, {1, 0, 6}));
	score.add(frame, mask, movers);
	frame.seq = 9;
	frame.points.pop_back();
	frame.groups = mover_1_only;
	score.add(frame, mask, movers);
	EXPECT_EQ(score.frames_separated, 9U);
	EXPECT_EQ(score.frames_seen, 1U);
	EXPECT_EQ(score.count_exact_seen, 1U);
	EXPECT_EQ(score.by_mover[1].unseen, 7U);
	EXPECT_EQ(score.by_mover[2].unseen, 8U);
	EXPECT_EQ(score.by_mover[2].missed, 6U);
	EXPECT_EQ(score.by_mover[2].missed_unseen, 6U);
	EXPECT_NE(tools::group_count_table("t", score).find("| 1 | 1.000 |"), std::string::npos)
		<< tools::group_count_table("t", score);
}

// The still-camera reference (tools/motion_reference.hpp): the median of samples is the empty scene even
// when a mover crosses some of them, and a mover's blob is found, noise is not.
TEST(MotionReference, MedianIgnoresAMoverAndTheMaskFindsIt)
{
	const cv::Mat scene(60, 80, CV_8UC3, cv::Scalar(100, 120, 140));
	std::vector<cv::Mat> samples;
	for (int k = 0; k < 7; ++k) {
		cv::Mat s = scene.clone();
		if (k < 3) // a dark mover in 3 of 7 samples, at a different place each time
			cv::rectangle(s, cv::Rect(5 + 20 * k, 10, 15, 30), cv::Scalar(10, 10, 10), cv::FILLED);
		samples.push_back(s);
	}
	const cv::Mat background = tools::median_background(samples);
	EXPECT_EQ(cv::norm(background, scene, cv::NORM_INF), 0);

	cv::Mat frame = scene.clone();
	cv::rectangle(frame, cv::Rect(30, 15, 16, 30), cv::Scalar(20, 200, 20), cv::FILLED); // a mover: 480 px
	frame.at<cv::Vec3b>(5, 5) = cv::Vec3b(255, 255, 255);				     // one noisy pixel
	tools::MotionReferenceParams params;
	params.dilate_radius_px = 0;
	const cv::Mat mask = tools::mover_mask(frame, background, params);
	EXPECT_EQ(mask.at<uint8_t>(30, 38), 1);
	EXPECT_EQ(mask.at<uint8_t>(5, 5), 0);
	EXPECT_NEAR(cv::countNonZero(mask), 16 * 30, 4); // the opening (a 3 x 3 cross) rounds the 4 corners
	params.min_area_px = 1000;			 // larger than the mover: nothing kept
	EXPECT_EQ(cv::countNonZero(tools::mover_mask(frame, background, params)), 0);
}

// A pixels-only reference (stereoctl reference writes no "objects"): every mask id with enough pixels is a
// mover; counts and coverage are scored, nothing metric, and its per-frame ids make no id switches.
TEST(GroupEvaluation, PixelsOnlyReferenceScoresCountsAndCoverage)
{
	cv::Mat mask(240, 480, CV_8UC1, cv::Scalar(0));
	mask(cv::Rect(100, 50, 40, 100)).setTo(1);
	mask(cv::Rect(300, 60, 40, 100)).setTo(2);
	mask(cv::Rect(10, 10, 10, 10)).setTo(3); // 100 px: too small to count
	const auto movers =
		tools::visible_movers(mask, nlohmann::json::parse(R"({"seq":4,"mask":"masks/000004.png"})"), 400);
	ASSERT_EQ(movers.size(), 2U);
	EXPECT_FALSE(movers[0].metric);
	tools::GroupScore score;
	FrameResult frame;
	frame.groups = {group_at(7, {98, 48, 44, 104}, 1.65, 0, {-1, 0, 5.3})};
	score.add(frame, mask, movers);
	frame.groups = {group_at(9, {98, 48, 44, 104}, 1.65, 0, {-1, 0, 5.3}),
			group_at(10, {300, 60, 40, 100}, 1.0, 0.0, {1, 0, 6})};
	score.add(frame, mask, movers);
	EXPECT_EQ(score.count_exact, 1U);
	EXPECT_EQ(score.movers_covered, 3U);
	EXPECT_EQ(score.id_switches, 0U) << "mask ids of a pixels-only reference are per frame";
	EXPECT_TRUE(score.centroid_error_m.empty());
	EXPECT_TRUE(score.speed_relative_error.empty());
	EXPECT_EQ(score.movers_inside, 3U);
	EXPECT_EQ(score.movers_untouched, 1U) << "mover 2 in the first frame: no box reaches it";
	// A third frame: mover 1 found as two groups (one of them inside the other), mover 2 missed.
	frame.groups = {group_at(11, {98, 48, 44, 104}, 1.65, 0, {-1, 0, 5.3}),
			group_at(12, {100, 100, 40, 50}, 1.65, 0, {-1, 0, 5.3})};
	score.add(frame, mask, movers);
	EXPECT_EQ(score.frames_separated, 3U);
	EXPECT_EQ(score.count_exact, 2U) << "two groups for two movers, though both on mover 1";
	EXPECT_EQ(score.count_over, 0U);
	EXPECT_EQ(score.count_under, 1U) << "the first frame";
	EXPECT_EQ(score.separated_mover_views, 6U);
	EXPECT_EQ(score.separated_movers_split, 1U);
	EXPECT_EQ(score.separated_movers_missed, 2U) << "mover 2 in the first and third frames";
	EXPECT_EQ(score.separated_groups, 5U);
	EXPECT_EQ(score.separated_groups_off, 0U);
}

// A pixels-only reference takes in people standing still; the acceptance counts the frames where they walk.
// mark_walking compares each blob with the blob overlapping it most some frames before and after.
TEST(GroupEvaluation, WalkingMoversFromTheReferencesOwnMasks)
{
	cv::Mat mask(240, 480, CV_8UC1, cv::Scalar(0)), before = mask.clone(), after = mask.clone();
	mask(cv::Rect(100, 50, 40, 100)).setTo(1);  // walks right: 12 px earlier, 12 px later
	before(cv::Rect(88, 50, 40, 100)).setTo(2); // (ids are per frame: not the same numbers)
	after(cv::Rect(112, 50, 40, 100)).setTo(1);
	mask(cv::Rect(300, 60, 40, 100)).setTo(2); // stands: 1 px earlier, 2 px later
	before(cv::Rect(300, 61, 40, 100)).setTo(1);
	after(cv::Rect(302, 60, 40, 100)).setTo(3);
	mask(cv::Rect(400, 100, 30, 100)).setTo(3); // only in this frame: unknown, so it counts as walking
	auto movers = tools::visible_movers(mask, nlohmann::json::parse(R"({"seq":4})"), 400);
	ASSERT_EQ(movers.size(), 3U);
	tools::mark_walking(movers, mask, before, after, 5);
	EXPECT_TRUE(movers[0].walking);
	EXPECT_FALSE(movers[1].walking);
	EXPECT_TRUE(movers[2].walking);
	// Without the frame before (the start of the video) the frame after decides; the threshold is inclusive
	// of a move that long.
	tools::mark_walking(movers, mask, cv::Mat(), after, 12);
	EXPECT_TRUE(movers[0].walking);
	EXPECT_FALSE(movers[1].walking);
	tools::mark_walking(movers, mask, cv::Mat(), after, 13);
	EXPECT_FALSE(movers[0].walking);
	// Covered views are counted among the walking ones apart.
	tools::GroupScore score;
	FrameResult frame;
	frame.groups = {group_at(7, {98, 48, 44, 104}, 1.65, 0, {-1, 0, 5.3}),
			group_at(8, {300, 60, 40, 100}, 1.0, 0.0, {1, 0, 6})};
	tools::mark_walking(movers, mask, before, after, 5);
	score.add(frame, mask, movers);
	EXPECT_EQ(score.mover_views, 3U);
	EXPECT_EQ(score.movers_covered, 2U);
	EXPECT_EQ(score.walking_views, 2U);
	EXPECT_EQ(score.walking_covered, 1U);
	// The labels against the walkers: the standing mover's points count for nothing either way.
	tools::GroupScore labels;
	FrameResult points;
	points.points = {
		LabelledPoint{110, 60, PointLabel::Dynamic, 110, 60, 0, std::nullopt},	 // walker: found
		LabelledPoint{120, 70, PointLabel::Static, 120, 70, 0, std::nullopt},	 // walker: missed
		LabelledPoint{410, 150, PointLabel::Dynamic, 410, 150, 0, std::nullopt}, // walker (unknown): found
		LabelledPoint{310, 70, PointLabel::Static, 310, 70, 0, std::nullopt},	 // standing: not counted
		LabelledPoint{320, 80, PointLabel::Dynamic, 320, 80, 0, std::nullopt},	 // standing: not counted
		LabelledPoint{20, 20, PointLabel::Dynamic, 20, 20, 0, std::nullopt},	 // scene: wrong
		LabelledPoint{30, 20, PointLabel::Static, 30, 20, 0, std::nullopt},	 // scene: right
	};
	labels.add(points, mask, movers);
	EXPECT_EQ(labels.walking_labels.dynamic_true, 2U);
	EXPECT_EQ(labels.walking_labels.static_false, 1U);
	EXPECT_EQ(labels.walking_labels.dynamic_false, 1U);
	EXPECT_EQ(labels.walking_labels.static_true, 1U);
	EXPECT_NEAR(labels.walking_labels.precision(), 2.0 / 3, 1e-9);
	EXPECT_NEAR(labels.walking_labels.recall(), 2.0 / 3, 1e-9);
}

// "Inside a group box" counts a mover whose pixels lie mostly in the box of a group on a mover even when that
// group is another mover's (two people side by side in one box); a box that only clips a mover, or is on
// the background, does not count, and a mover no box reaches is counted apart.
TEST(GroupEvaluation, MoversInsideABoxAndUntouched)
{
	cv::Mat mask(240, 480, CV_8UC1, cv::Scalar(0));
	mask(cv::Rect(100, 50, 40, 100)).setTo(1); // 4000 px
	mask(cv::Rect(150, 60, 30, 80)).setTo(2);  // 2400 px, beside mover 1
	mask(cv::Rect(300, 60, 40, 100)).setTo(3);
	mask(cv::Rect(400, 20, 30, 60)).setTo(4);
	const auto movers =
		tools::visible_movers(mask, nlohmann::json::parse(R"({"seq":1,"mask":"masks/000001.png"})"), 400);
	ASSERT_EQ(movers.size(), 4U);
	tools::GroupScore score;
	FrameResult frame;
	frame.groups = {group_at(1, {98, 48, 84, 104}, 1, 0, {0, 0, 5}),  // both 1 and 2: 1's by the most pixels
			group_at(2, {300, 60, 40, 30}, 1, 0, {0, 0, 5})}; // the top 30 % of mover 3
	score.add(frame, mask, movers);
	EXPECT_EQ(score.mover_views, 4U);
	EXPECT_EQ(score.movers_covered, 2U) << "movers 1 and 3";
	EXPECT_EQ(score.movers_inside, 2U) << "movers 1 and 2, not 3 (30 % inside)";
	EXPECT_EQ(score.movers_untouched, 1U) << "mover 4; mover 2 is reached by 1's box";
}
