// The pair stage's following of corners the detector loses (matching.follow_lost), on constructed data.
#include <gtest/gtest.h>

#include <array>

#include <opencv2/imgproc.hpp>

#include "core/vision/matching.hpp"
#include "core/vision/motion_stages.hpp"
#include "test_images.hpp"

using namespace stereod;
using namespace stereod::vision;

namespace {

/// Smoothed noise in BGR: corners everywhere, no repeated pattern.
cv::Mat texture(cv::Size size, uint64_t seed)
{
	cv::Mat bgr;
	cv::cvtColor(test::smoothed_noise(size, seed, 2.0), bgr, cv::COLOR_GRAY2BGR);
	return bgr;
}

using test::shifted;

/// `features` without every keypoint `drop` says to drop: what a detector that loses corners leaves.
FrameFeatures without(const FrameFeatures &features, const std::vector<uint8_t> &drop)
{
	FrameFeatures kept = features;
	kept.keypoints.clear();
	kept.colours.clear();
	kept.xyz.clear();
	kept.depth_on_edge.clear();
	kept.descriptors = cv::Mat();
	for (size_t i = 0; i < features.keypoints.size(); ++i) {
		if (drop[i] != 0)
			continue;
		kept.keypoints.push_back(features.keypoints[i]);
		kept.colours.push_back(features.colours[i]);
		kept.descriptors.push_back(features.descriptors.row(static_cast<int>(i)));
		if (i < features.xyz.size())
			kept.xyz.push_back(features.xyz[i]);
		if (i < features.depth_on_edge.size())
			kept.depth_on_edge.push_back(features.depth_on_edge[i]);
	}
	return kept;
}

/// Three frames' features through the pair stage in order, the third's detector having lost every corner inside
/// `region` (taken out of its features before).
struct LostRun {
	TrackSet t1, t2;
	std::array<FrameResult, 3> results;
	size_t kept_detected = 0;	  ///< the third frame's keypoints left; those the pair stage added follow
	std::vector<cv::Point2f> dropped; ///< where the lost corners were
};

LostRun lose_region_and_pair(std::array<FrameFeatures, 3> &features, const std::array<StereoFrame, 3> &frames,
			     const MotionParams &params, const cv::Rect2f &region)
{
	LostRun run;
	std::vector<uint8_t> drop(features[2].keypoints.size(), 0);
	for (size_t i = 0; i < drop.size(); ++i)
		if (region.contains(features[2].keypoints[i].pt)) {
			drop[i] = 1;
			run.dropped.push_back(features[2].keypoints[i].pt);
		}
	features[2] = without(features[2], drop);
	run.kept_detected = features[2].keypoints.size();
	StageWorkspace workspace;
	const TrackSet t0 = pair_stage(nullptr, nullptr, features[0], frames[0], params, run.results[0], workspace);
	run.t1 = pair_stage(&features[0], &t0, features[1], frames[1], params, run.results[1], workspace);
	run.t2 = pair_stage(&features[1], &run.t1, features[2], frames[2], params, run.results[2], workspace);
	return run;
}

} // namespace

TEST(LostCorners, SkipEdgesAndCornersFollowedAlready)
{
	FrameFeatures cur;
	cur.keypoints = {cv::KeyPoint(100, 100, 7), cv::KeyPoint(200, 50, 7), cv::KeyPoint(300, 300, 7)};
	const std::vector<Match> matches = {{0, 0, 10}, {1, 1, 12}}; // keypoint 2 is matched to nothing
	const std::vector<FollowedPoint> followed = {
		{2, {101.5F, 100.5F}, {0, 0}}, // within 2 px of matched keypoint 0: followed already
		{3, {103, 100}, {0, 0}},       // 3 px from it: a corner of its own
		{4, {300.5F, 300}, {0, 0}},    // beside keypoint 2, which nothing matched: kept
		{5, {200, 51.9F}, {0, 0}},     // 1.9 px below matched keypoint 1
		{6, {400, 400}, {1, 0}},       // on an edge: Lucas-Kanade slid along it
		{7, {400, 100}, {0, 0}},       // alone
	};
	const std::vector<FollowedPoint> kept = lost_corners(followed, cur, matches, 2);
	std::vector<int> prev;
	for (const FollowedPoint &f : kept)
		prev.push_back(f.prev);
	EXPECT_EQ(prev, (std::vector<int>{3, 4, 7}));
	EXPECT_EQ(lost_corners(followed, cur, matches, 0).size(), 5U); // no clearance: only the edge point goes
	EXPECT_TRUE(lost_corners({}, cur, matches, 2).empty());
}

// Three frames of a textured scene panning by (3.4, -1.8) px a frame. In the third frame the detector loses every
// corner in one region (they are taken out of its features), as it loses a mover's corners that change shape.
// The tracks of those corners end there without follow_lost; with it they go on, at the place the image moved
// to, with the corner's descriptor.
TEST(PairStage, CornersTheDetectorLosesAreFollowedOn)
{
	const cv::Size size(480, 360);
	const cv::Point2f step(3.4F, -1.8F);
	const cv::Mat scene = texture(size, 7);
	std::array<StereoFrame, 3> frames;
	for (size_t k = 0; k < frames.size(); ++k) {
		frames[k].left = shifted(scene, step * static_cast<float>(k));
		frames[k].sequence = k;
		frames[k].device_ns = static_cast<int64_t>(k) * 100'000'000;
	}
	const auto run = [&](bool follow_lost, size_t &lost, size_t &found_again) {
		MotionParams params;
		params.features.max_features = 600;
		params.matching.follow_lost = follow_lost;
		std::vector<StageTime> timing;
		std::array<FrameFeatures, 3> features;
		for (size_t k = 0; k < 3; ++k)
			features[k] = extract_stage(frames[k], params, timing);
		// The third frame's detector loses every corner in the middle of the image.
		const cv::Rect2f region(140, 100, 200, 160);
		const LostRun lost_run = lose_region_and_pair(features, frames, params, region);
		const size_t kept_detected = lost_run.kept_detected;
		const TrackSet &t2 = lost_run.t2;
		const FrameResult &r2 = lost_run.results[2];
		const std::vector<cv::Point2f> &dropped = lost_run.dropped;
		// The grown features stay one record per keypoint, and the memory covers every one of them.
		const FrameFeatures &grown = features[2];
		EXPECT_EQ(static_cast<size_t>(grown.descriptors.rows), grown.keypoints.size());
		EXPECT_EQ(grown.colours.size(), grown.keypoints.size());
		EXPECT_EQ(t2.by_keypoint.size(), grown.keypoints.size());
		// Each added keypoint (in the region, and wherever else the detector lost a corner by itself) sits
		// where the image moved a keypoint of the frame before, and carries that keypoint's descriptor (ORB
		// finds a corner at several scales: any of those there).
		for (size_t c = kept_detected; c < grown.keypoints.size(); ++c) {
			const cv::Point2f at = grown.keypoints[c].pt;
			bool carried = false;
			for (size_t p = 0; p < features[1].keypoints.size() && !carried; ++p)
				carried = cv::norm(features[1].keypoints[p].pt + step - at) < 0.3 &&
					  cv::norm(grown.descriptors.row(static_cast<int>(c)),
						   features[1].descriptors.row(static_cast<int>(p)),
						   cv::NORM_HAMMING) == 0;
			EXPECT_TRUE(carried) << "kept at " << at;
		}
		// Of the lost corners, how many this frame's points hold again.
		lost = dropped.size();
		found_again = 0;
		for (const cv::Point2f at : dropped)
			found_again += std::any_of(r2.points.begin(), r2.points.end(), [&](const auto &point) {
				return std::hypot(point.u - at.x, point.v - at.y) < 1.5;
			});
		return grown.keypoints.size() - kept_detected;
	};
	size_t lost_off = 0, found_off = 0, lost_on = 0, found_on = 0;
	EXPECT_EQ(run(false, lost_off, found_off), 0U);
	const size_t added = run(true, lost_on, found_on);
	ASSERT_EQ(lost_on, lost_off);
	ASSERT_GT(lost_on, 60U); // measured: 164 lost, 1 held again without follow_lost, 136 with it
	// Without it nothing holds them (a point within 1.5 px of one lies outside the region only).
	EXPECT_LT(found_off, lost_off / 10);
	// With it most are: those whose track was a frame old (matched from the first frame to the second).
	EXPECT_GT(found_on, lost_on * 6 / 10);
	EXPECT_GE(added + found_off, found_on);
}

// The same with a calibrated stereo pair of a plane 5 m away (a 10 px disparity): a followed corner keeps its
// track's id, gets the plane's depth from the row search, and keeps the static scene's label.
TEST(PairStage, ALostCornerKeepsItsTrackDepthAndLabel)
{
	const cv::Size size(480, 360);
	const geometry::StereoRig rig{500, 500, 240, 180, 0.1};
	const double disparity = 10, depth = rig.depth(disparity);
	const cv::Point2f step(3.4F, -1.8F);
	const cv::Mat scene = texture(size, 11);
	std::array<StereoFrame, 3> frames;
	for (size_t k = 0; k < frames.size(); ++k) {
		frames[k].left = shifted(scene, step * static_cast<float>(k));
		frames[k].right = shifted(frames[k].left, {static_cast<float>(-disparity), 0});
		frames[k].sequence = k;
		frames[k].device_ns = static_cast<int64_t>(k) * 100'000'000;
	}
	MotionParams params;
	params.features.max_features = 600;
	params.rig = rig;
	std::vector<StageTime> timing;
	std::array<FrameFeatures, 3> features;
	for (size_t k = 0; k < 3; ++k)
		features[k] = extract_stage(frames[k], params, timing);
	ASSERT_EQ(features[2].xyz.size(), features[2].keypoints.size());
	const cv::Rect2f region(140, 100, 200, 160);
	const LostRun run = lose_region_and_pair(features, frames, params, region);
	const size_t kept_detected = run.kept_detected;
	const TrackSet &t1 = run.t1, &t2 = run.t2;
	const FrameResult &r2 = run.results[2];
	const FrameFeatures &grown = features[2];
	ASSERT_EQ(grown.xyz.size(), grown.keypoints.size());
	ASSERT_EQ(grown.depth_on_edge.size(), grown.keypoints.size());
	ASSERT_EQ(t2.by_keypoint.size(), grown.keypoints.size());
	size_t in_region = 0, same_track = 0;
	for (size_t c = kept_detected; c < grown.keypoints.size(); ++c) {
		const cv::Point2f at = grown.keypoints[c].pt;
		in_region += region.contains(at) ? 1 : 0;
		EXPECT_NEAR(grown.xyz[c][2], depth, depth * 0.02) << "at " << at;
		EXPECT_EQ(grown.depth_on_edge[c], 0);
		// The predecessor: the keypoint of the frame before that the image moved here. Its track goes on.
		for (size_t p = 0; p < features[1].keypoints.size(); ++p)
			if (cv::norm(features[1].keypoints[p].pt + step - at) < 0.3 &&
			    t1.by_keypoint[p].id == t2.by_keypoint[c].id && t2.by_keypoint[c].id != 0) {
				++same_track;
				break;
			}
	}
	const size_t added = grown.keypoints.size() - kept_detected;
	EXPECT_GT(in_region, 60U); // measured: 94 here, and all 129 added corners on their track
	EXPECT_EQ(same_track, added);
	// Their points are published with the plane's depth, and none is dynamic: the scene is one rigid plane.
	size_t published = 0;
	for (const LabelledPoint &point : r2.points) {
		if (!region.contains({point.u, point.v}))
			continue;
		++published;
		EXPECT_NE(point.label, PointLabel::Dynamic) << point.u << ", " << point.v;
		ASSERT_TRUE(point.xyz_m.has_value());
		EXPECT_NEAR((*point.xyz_m)[2], depth, depth * 0.02);
	}
	EXPECT_GE(published, in_region * 9 / 10);
}
