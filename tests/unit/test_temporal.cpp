// The motion memory (core/vision/temporal.hpp) on constructed tracks with known answers.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include <opencv2/imgproc.hpp>

#include "core/vision/classifier.hpp"
#include "core/vision/temporal.hpp"

using namespace stereod;
using namespace stereod::vision;

namespace {

constexpr int64_t kFrameNs = 33'333'333; // 30 frames per second

/// Follows `prev_positions[i] -> cur_positions[i]` (keypoint i to keypoint i) over a flat grey image, where
/// every texture check passes, with the static scene not moving (identity homography).
struct Follower {
	cv::Mat image = cv::Mat(480, 640, CV_8UC3, cv::Scalar::all(128));
	cv::Matx33d still = cv::Matx33d::eye();
	ClassifierParams classifier;
	TemporalParams params;
	TrackSet tracks;
	int64_t t_ns = 0;
	bool started = false;

	void step(const std::vector<cv::Point2f> &prev_positions, const std::vector<cv::Point2f> &cur_positions)
	{
		std::vector<Match> matches;
		std::vector<PointPair> pairs;
		for (size_t i = 0; i < cur_positions.size(); ++i) {
			matches.push_back({static_cast<int>(i), static_cast<int>(i), 0});
			pairs.push_back(
				{prev_positions[i], cur_positions[i], cv::Vec3f::all(128), cv::Vec3f::all(128)});
		}
		// The texture check, as classify() makes it for every pair against frame n.
		std::vector<uint8_t> agrees;
		for (const auto &pair : pairs)
			agrees.push_back(texture_distance_near(pair.prev_colour, image, pair.cur, classifier) <
					 classifier.texture_threshold);
		t_ns += kFrameNs;
		FollowInput input;
		input.matches = matches;
		input.pairs = pairs;
		input.homography = &still;
		input.texture_agrees = agrees;
		input.cur_keypoints = cur_positions.size();
		input.t_ns = t_ns;
		tracks = follow_tracks(started ? &tracks : nullptr, input, classifier, params);
		started = true;
	}
	[[nodiscard]] bool moving(size_t keypoint) const
	{
		return memory_says_moving(tracks.by_keypoint[keypoint], classifier, params);
	}
};

} // namespace

TEST(MotionMemory, SlowMoverIsRememberedAndJitterIsNot)
{
	Follower f;
	// Keypoint 0: a static corner whose detected position jumps +-0.8 px from frame to frame.
	// Keypoint 1: a mover at 0.8 px per frame, well under the seed's per-frame gate (2.6 px each way).
	std::vector<cv::Point2f> prev = {{100, 100}, {300, 200}};
	f.step(prev, prev);
	const uint64_t mover_id = f.tracks.by_keypoint[1].id;
	int first_moving_frame = -1;
	for (int frame = 1; frame <= 45; ++frame) {
		const float jitter = frame % 2 == 0 ? 0.8F : -0.8F;
		std::vector<cv::Point2f> cur = {{100 + jitter, 100}, {300 + 0.8F * static_cast<float>(frame), 200}};
		f.step(prev, cur);
		prev = cur;
		EXPECT_FALSE(f.moving(0)) << "frame " << frame;
		if (first_moving_frame < 0 && f.moving(1))
			first_moving_frame = frame;
		EXPECT_EQ(f.tracks.by_keypoint[1].id, mover_id) << "followed, so the same track";
	}
	EXPECT_TRUE(f.moving(1));
	// The evidence needs several frames: never at once, and within about a window (15 frames here).
	EXPECT_GE(first_moving_frame, f.params.min_age);
	EXPECT_LE(first_moving_frame, 20);
	EXPECT_NE(f.tracks.by_keypoint[0].id, mover_id);
}

TEST(MotionMemory, MismatchJumpStartsAFreshTrack)
{
	Follower f;
	const std::vector<cv::Point2f> still = {{200, 200}};
	for (int frame = 0; frame < 10; ++frame)
		f.step(still, still);
	const TrackState before = f.tracks.by_keypoint[0];
	EXPECT_EQ(before.age, 9U);
	// A match onto a look-alike 25 px away: not followed, so no memory of motion comes of it.
	f.step(still, {{225, 200}});
	EXPECT_NE(f.tracks.by_keypoint[0].id, before.id);
	EXPECT_EQ(f.tracks.by_keypoint[0].age, 0U);
	EXPECT_FALSE(f.moving(0));
}

TEST(MotionMemory, DifferentTextureStartsAFreshTrack)
{
	Follower f;
	const std::vector<cv::Point2f> at = {{200, 200}};
	f.step(at, at);
	f.step(at, at);
	const uint64_t id = f.tracks.by_keypoint[0].id;
	cv::rectangle(f.image, cv::Rect(190, 190, 20, 20), cv::Scalar(0, 0, 255), cv::FILLED);
	f.step(at, at);
	EXPECT_NE(f.tracks.by_keypoint[0].id, id) << "the two ends no longer look alike";
}

TEST(MotionMemory, WindowZeroTurnsItOff)
{
	Follower f;
	f.params.window_s = 0;
	std::vector<cv::Point2f> prev = {{100, 100}};
	f.step(prev, prev);
	for (int frame = 1; frame <= 30; ++frame) {
		std::vector<cv::Point2f> cur = {{100 + 2.0F * static_cast<float>(frame), 100}};
		f.step(prev, cur);
		prev = cur;
	}
	EXPECT_FALSE(f.moving(0));
}

TEST(MotionMemory, PromotesOnlyRememberedMovers)
{
	TrackSet tracks;
	tracks.by_keypoint.resize(3);
	for (auto &state : tracks.by_keypoint) {
		state.age = 10;
		state.count = 8;
		state.noise_weight = 5;
	}
	tracks.by_keypoint[0].motion = {0.5F, 0.2F}; // static
	tracks.by_keypoint[1].motion = {12.0F, 0};   // moving: 144 / 5 > 9.21
	tracks.by_keypoint[2].motion = {12.0F, 0};
	std::vector<PointLabel> labels = {PointLabel::Static, PointLabel::Static, PointLabel::Dynamic};
	// The memory belongs to this frame's keypoints (Match::cur); the previous frame's indices are scrambled.
	const std::vector<Match> matches = {{2, 0, 0}, {0, 1, 0}, {1, 2, 0}};
	const int promoted = promote_remembered_movers(labels, matches, tracks, ClassifierParams{}, TemporalParams{});
	EXPECT_EQ(promoted, 1) << "only the static label that memory contradicts";
	EXPECT_EQ(labels[0], PointLabel::Static);
	EXPECT_EQ(labels[1], PointLabel::Dynamic);
	EXPECT_EQ(labels[2], PointLabel::Dynamic);
}

TEST(MotionMemory, KnownMoversDoNotVoteForTheHomography)
{
	// 120 static points shift 2 px right; 80 points on a slow mover shift 4 px: inside the 3 px RANSAC band
	// of the background's motion, so they pull a homography fitted to everything.
	std::mt19937 rng(5);
	std::uniform_real_distribution<float> x(20, 620), y(20, 460);
	std::normal_distribution<float> noise(0, 0.5F);
	std::vector<PointPair> pairs;
	std::vector<uint8_t> known(200, 0);
	for (int i = 0; i < 200; ++i) {
		const cv::Point2f p(x(rng), y(rng));
		const float shift = i < 120 ? 2.0F : 4.0F;
		const cv::Point2f seen(noise(rng), noise(rng));
		pairs.push_back({p, p + cv::Point2f(shift, 0) + seen, cv::Vec3f::all(128), cv::Vec3f::all(128)});
		known[static_cast<size_t>(i)] = i >= 120 ? 1 : 0;
	}
	const cv::Mat grey(480, 640, CV_8UC3, cv::Scalar::all(128));
	ClassifierParams params;
	const Classification blind = classify(pairs, grey, params);
	const Classification told = classify(pairs, grey, params, known);
	ASSERT_TRUE(blind.homography && told.homography);
	const cv::Point2f centre(320, 240);
	const float blind_shift = project(*blind.homography, centre).x - centre.x;
	const float told_shift = project(*told.homography, centre).x - centre.x;
	EXPECT_GT(std::abs(blind_shift - 2.0F), 0.2F) << "the mover drags the fit";
	EXPECT_LT(std::abs(told_shift - 2.0F), 0.1F);
}

TEST(MotionMemory, JumpStatisticIsTheInnovationOverItsVariance)
{
	ClassifierParams classifier;
	classifier.reprojection_sigma_px = 1.0;
	// A track of one frame: mean = that frame's own motion, whose noise equals the new frame's: the
	// innovation's variance per axis is 2 sigma^2 + 2 sigma^2 = 4.
	TrackState fresh;
	fresh.motion = {1, 0};
	fresh.count = 1;
	fresh.noise_weight = 1;
	EXPECT_NEAR(jump_statistic(fresh, {5, 0}, classifier), 16.0 / 4.0, 1e-6);
	// A long track: W / S^2 small, the variance tends to the new frame's own 2 sigma^2.
	TrackState old;
	old.motion = {20, 0};
	old.count = 20;
	old.noise_weight = 4; // W / S^2 = 0.01
	EXPECT_NEAR(jump_statistic(old, {1, 3}, classifier), 9.0 / (2.0 * 1.01), 1e-6);
}

TEST(MotionMemory, FramesASteadyMoverNeedsToBeRemembered)
{
	// The figure docs/classification.md quotes: frames until a steady mover at m px per frame (30 fps,
	// window 0.5 s, sigma 1) is remembered as moving, by the memory itself and by the closed form
	// |R_k|^2 / W_k = m^2 (1 - l^k)^2 / (1 - l)^2 * (1 - l^2) / (1 - l^(2k)) > chi2.
	for (const float m : {0.6F, 0.8F, 1.0F, 2.0F}) {
		Follower f;
		std::vector<cv::Point2f> prev = {{100, 300}};
		f.step(prev, prev);
		int first = -1;
		for (int frame = 1; frame <= 120 && first < 0; ++frame) {
			const std::vector<cv::Point2f> cur = {{100 + m * static_cast<float>(frame), 300}};
			f.step(prev, cur);
			prev = cur;
			if (f.moving(0))
				first = frame;
		}
		const double l = std::exp(-1.0 / 30.0 / f.params.window_s);
		int expected = -1;
		for (int k = 1; k <= 120 && expected < 0; ++k) {
			const double r = m * (1 - std::pow(l, k)) / (1 - l);
			const double w = (1 - std::pow(l, 2 * k)) / (1 - l * l);
			if (k >= f.params.min_age && r * r / w > f.params.chi2)
				expected = k;
		}
		EXPECT_EQ(first, expected) << "m = " << m;
		std::printf("steady mover at %.1f px/frame: remembered as moving after %d frames\n", m, first);
	}
}
