#include <gtest/gtest.h>

#include "tools/evaluation.hpp"

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
