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
