// The person prior (core/vision/person_prior.hpp) and its use in the pair stage, on constructed data.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "core/vision/motion_stages.hpp"
#include "core/vision/person_prior.hpp"

using namespace stereod;
using namespace stereod::vision;

namespace {

PriorRegion region(float x, float y, float w, float h, PriorCategory category = PriorCategory::Dynamic, int age = 0)
{
	PriorRegion r;
	r.box = cv::Rect2f(x, y, w, h);
	r.score = 1.5F;
	r.category = category;
	r.age_frames = age;
	return r;
}

/// Blurred noise: corners everywhere, no repeated pattern.
cv::Mat texture(cv::Size size, uint64_t seed)
{
	cv::Mat noise(size, CV_8UC1);
	cv::RNG rng(seed);
	rng.fill(noise, cv::RNG::UNIFORM, 0, 256);
	cv::GaussianBlur(noise, noise, cv::Size(5, 5), 1.2);
	cv::Mat bgr;
	cv::cvtColor(noise, bgr, cv::COLOR_GRAY2BGR);
	return bgr;
}

} // namespace

TEST(PersonPrior, CarriedBoxesMoveWithTheirPointsAndAge)
{
	const std::vector<PriorRegion> regions = {region(10, 10, 20, 40),
						  region(100, 100, 10, 10, PriorCategory::Dynamic, 4)};
	// Three points in the first box move by (3, -1); one outlier inside it by (40, 40); none in the second.
	const std::vector<cv::Point2f> from = {{12, 12}, {20, 30}, {25, 45}, {15, 20}, {200, 200}};
	const std::vector<cv::Point2f> to = {{15, 11}, {23, 29}, {28, 44}, {55, 60}, {200, 200}};
	const auto carried = carry_regions(regions, from, to, 5);
	ASSERT_EQ(carried.size(), 2U);
	EXPECT_FLOAT_EQ(carried[0].box.x, 13); // the median displacement: the outlier does not move the box
	EXPECT_FLOAT_EQ(carried[0].box.y, 9);
	EXPECT_FLOAT_EQ(carried[0].box.width, 20);
	EXPECT_EQ(carried[0].age_frames, 1);
	EXPECT_FLOAT_EQ(carried[1].box.x, 100); // nothing inside: stays where it was
	EXPECT_EQ(carried[1].age_frames, 5);
	// One frame later the second box is older than max_age_frames and is forgotten.
	const auto again = carry_regions(carried, to, to, 5);
	ASSERT_EQ(again.size(), 1U);
	EXPECT_EQ(again[0].age_frames, 2);
}

TEST(PersonPrior, OnlyTheDynamicCategoryMarksPoints)
{
	const std::vector<PriorRegion> regions = {region(0, 0, 10, 10),
						  region(50, 50, 10, 10, PriorCategory::PotentiallyDynamic)};
	const std::vector<cv::Point2f> points = {{5, 5}, {55, 55}, {20, 20}, {9.9F, 0}};
	EXPECT_EQ(in_dynamic_category(points, regions), (std::vector<uint8_t>{1, 0, 0, 1}));
}

TEST(PersonPrior, DetectorFindsNobodyInEmptyOrFeaturelessImages)
{
	PersonPriorParams params;
	EXPECT_TRUE(detect_people(cv::Mat(), params).empty());
	EXPECT_TRUE(detect_people(cv::Mat(40, 30, CV_8UC1, cv::Scalar(0)), params).empty()); // smaller than a window
	EXPECT_TRUE(detect_people(cv::Mat(480, 640, CV_8UC1, cv::Scalar(128)), params).empty());
}

// Seed 001: points of the dynamic category take no part in the motion fit. A textured "person" covering most
// of the image moves 6 px while the background stands still: fitted over every point, the static scene's
// motion follows the majority (the person) and the background comes out moving; with the person's box in
// the prior, the fit uses the background and the labels are right.
TEST(PersonPrior, PointsInAPersonBoxLeaveTheMotionFit)
{
	const cv::Size size(320, 240);
	const cv::Mat background = texture(size, 1);
	const cv::Mat person = texture(cv::Size(220, 200), 2);
	StereoFrame f0, f1;
	f0.left = background.clone();
	person.copyTo(f0.left(cv::Rect(40, 20, 220, 200)));
	f1.left = background.clone();
	person.copyTo(f1.left(cv::Rect(46, 20, 220, 200)));
	f0.sequence = 0;
	f1.sequence = 1;
	f1.device_ns = 100'000'000;
	const cv::Rect2f person_box(40, 14, 232, 212);

	const auto run = [&](bool prior) {
		MotionParams params;
		params.prior.enabled = prior;
		params.prior.every_n_frames = 1000; // the detector never runs: the box is given
		// Descriptor matches only: over this single frame pair the rescue adds 76 matches inside the box,
		// undecided more often (59 % dynamic) with no track behind them; the prior is what is tested here.
		params.matching.rescue = false;
		std::vector<StageTime> timing;
		FrameFeatures a = extract_stage(f0, params, timing);
		FrameFeatures b = extract_stage(f1, params, timing);
		if (prior) {
			a.people = std::vector<PriorRegion>{region(40, 14, 232, 212)};
			b.people = std::vector<PriorRegion>{region(46, 14, 232, 212)};
		}
		FrameResult first, second;
		StageWorkspace workspace;
		const TrackSet t0 = pair_stage(nullptr, nullptr, a, f0, params, first, workspace);
		pair_stage(&a, &t0, b, f1, params, second, workspace);
		int outside = 0, outside_static = 0, inside = 0, inside_dynamic = 0;
		for (const auto &p : second.points) {
			const bool in = person_box.contains({p.prev_u, p.prev_v}) && p.prev_u > 48 && p.prev_u < 258;
			if (in) {
				++inside;
				inside_dynamic += p.label == PointLabel::Dynamic;
				EXPECT_TRUE(!prior || p.in_person);
			} else if (!person_box.contains({p.u, p.v})) {
				++outside;
				outside_static += p.label == PointLabel::Static;
			}
		}
		EXPECT_GT(inside, 50);
		EXPECT_GT(outside, 10);
		if (prior) {
			EXPECT_FALSE(second.people.empty());
		}
		return std::pair{static_cast<double>(outside_static) / outside,
				 static_cast<double>(inside_dynamic) / inside};
	};
	const auto [without_bg_static, without_person_dynamic] = run(false);
	const auto [with_bg_static, with_person_dynamic] = run(true);
	EXPECT_LT(without_bg_static, 0.5) << "the fit should have followed the majority";
	EXPECT_LT(without_person_dynamic, 0.5);
	EXPECT_GT(with_bg_static, 0.8);
	EXPECT_GT(with_person_dynamic, 0.8);
}

// GroupParams::keep_labels_in_box: a mover's part that stands still for a frame (a walker's stance foot)
// keeps the dynamic label it was published with, while it lies inside the mover's group box; without the
// rule it is static, since it did not move.
TEST(GroupLabels, APartStandingStillInsideTheBoxKeepsItsLabel)
{
	const cv::Size size(320, 240);
	const cv::Mat background = texture(size, 3);
	const cv::Mat body = texture(cv::Size(100, 140), 4);
	constexpr int kFrames = 7, kStep = 6;
	// The part standing still in the last frame: a square in the middle of the body, where it was the frame
	// before, while the rest of the body moves on.
	const cv::Rect still(40 + (kFrames - 2) * kStep + 35, 70, 30, 40);
	std::vector<StereoFrame> frames(kFrames);
	for (int k = 0; k < kFrames; ++k) {
		frames[k].left = background.clone();
		body.copyTo(frames[k].left(cv::Rect(40 + k * kStep, 50, body.cols, body.rows)));
		frames[k].sequence = static_cast<uint64_t>(k);
		frames[k].device_ns = k * 100'000'000LL;
	}
	frames[kFrames - 2].left(still).copyTo(frames[kFrames - 1].left(still));
	const auto run = [&](bool keep) {
		MotionParams params;
		params.groups.keep_labels_in_box = keep;
		params.groups.new_in_box_frames = 0; // this rule alone (the body's corners are new in the still part)
		std::vector<StageTime> timing;
		StageWorkspace workspace;
		std::vector<FrameFeatures> features;
		std::vector<TrackSet> tracks;
		FrameResult result;
		for (int k = 0; k < kFrames; ++k) {
			features.push_back(extract_stage(frames[k], params, timing));
			result = FrameResult{};
			tracks.push_back(pair_stage(k > 0 ? &features[static_cast<size_t>(k - 1)] : nullptr,
						    k > 0 ? &tracks.back() : nullptr, features.back(), frames[k],
						    params, result, workspace));
		}
		// The last frame's points well inside the still part: how many, and how many dynamic.
		const cv::Rect inner(still.x + 6, still.y + 6, still.width - 12, still.height - 12);
		int inside = 0, dynamic = 0, boxes_over = 0;
		for (const LabelledPoint &p : result.points)
			if (inner.contains(cv::Point(cvRound(p.u), cvRound(p.v)))) {
				++inside;
				dynamic += p.label == PointLabel::Dynamic ? 1 : 0;
			}
		for (const TargetGroup &g : result.groups)
			boxes_over += g.box_px[0] <= still.x && g.box_px[2] >= still.br().x ? 1 : 0;
		return std::array<int, 3>{inside, dynamic, boxes_over};
	};
	// Measured: 10 points there, none dynamic without the rule, all 10 with it.
	const auto off = run(false), on = run(true);
	ASSERT_GE(on[2], 1) << "the body is a group whose box covers the still part";
	ASSERT_GE(off[0], 3);
	EXPECT_LE(off[1], off[0] / 3) << "without the rule the still part is mostly static";
	EXPECT_GE(on[1], on[0] * 2 / 3) << "with it, mostly dynamic";
}
