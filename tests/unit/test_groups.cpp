// Affinity Propagation and the grouping of moving points, on constructed data with known answers.
#include <algorithm>
#include <array>
#include <limits>
#include <random>
#include <set>

#include <gtest/gtest.h>

#include "core/vision/affinity.hpp"
#include "core/vision/groups.hpp"

using namespace stereod;
using namespace stereod::vision;

namespace {

/// `per_blob` points around each centre, normal with sigma 1, fixed seed.
cv::Mat blobs(const std::vector<cv::Point2f> &centres, int per_blob, unsigned seed = 7)
{
	std::mt19937 rng(seed);
	std::normal_distribution<float> noise(0.f, 1.f);
	cv::Mat samples(static_cast<int>(centres.size()) * per_blob, 2, CV_32F);
	int row = 0;
	for (const auto &c : centres)
		for (int i = 0; i < per_blob; ++i, ++row) {
			samples.at<float>(row, 0) = c.x + noise(rng);
			samples.at<float>(row, 1) = c.y + noise(rng);
		}
	return samples;
}

} // namespace

TEST(AffinityPropagation, FindsSeparatedBlobsWithoutBeingToldHowMany)
{
	for (const auto &centres : std::vector<std::vector<cv::Point2f>>{
		     {{0, 0}, {20, 0}, {0, 20}}, {{0, 0}, {25, 5}}, {{0, 0}, {20, 20}, {40, 0}, {-20, 30}, {60, 40}}}) {
		const int per_blob = 40;
		const cv::Mat samples = blobs(centres, per_blob);
		AffinityPropagation ap;
		const AffinityResult &result = ap.cluster(samples, AffinityParams{});
		EXPECT_TRUE(result.converged);
		EXPECT_EQ(result.clusters, static_cast<int>(centres.size()));
		// Every blob is one cluster and no two blobs share one.
		for (size_t b = 0; b < centres.size(); ++b) {
			const int exemplar = result.exemplar[b * per_blob];
			for (int i = 0; i < per_blob; ++i)
				EXPECT_EQ(result.exemplar[b * per_blob + static_cast<size_t>(i)], exemplar)
					<< "blob " << b;
			for (size_t other = b + 1; other < centres.size(); ++other)
				EXPECT_NE(result.exemplar[other * per_blob], exemplar);
		}
	}
}

TEST(AffinityPropagation, SparseWithAllNeighboursIsTheDenseAlgorithm)
{
	const cv::Mat samples = blobs({{0, 0}, {12, 3}, {5, 14}}, 20, 3);
	AffinityParams params;
	params.neighbours = samples.rows - 1;
	AffinityPropagation ap;
	const AffinityResult sparse = ap.cluster(samples, params);
	const AffinityResult dense = affinity_propagation_dense(samples, params);
	EXPECT_EQ(sparse.clusters, dense.clusters);
	EXPECT_EQ(sparse.iterations, dense.iterations);
	EXPECT_EQ(sparse.exemplar, dense.exemplar);
	EXPECT_DOUBLE_EQ(sparse.preference, dense.preference);
}

TEST(AffinityPropagation, PreferenceSetsHowManyClusters)
{
	const cv::Mat samples = blobs({{0, 0}, {20, 0}, {0, 20}}, 30);
	AffinityPropagation ap;
	AffinityParams seed; // the minimum similarity: the three blobs
	EXPECT_EQ(ap.cluster(samples, seed).clusters, 3);
	AffinityParams fewer = seed; // lower, with every sample linked
	fewer.preference_scale = 4;
	fewer.neighbours = samples.rows - 1;
	EXPECT_LE(ap.cluster(samples, fewer).clusters, 3);
	AffinityParams joined = fewer; // a preference far below the blobs' separation: one cluster
	joined.preference_scale = 1;
	joined.preference = -20000;
	joined.damping = 0.9;
	EXPECT_EQ(ap.cluster(samples, joined).clusters, 1);
	AffinityParams many;
	many.preference = -0.01; // above most similarities: many small clusters
	EXPECT_GT(ap.cluster(samples, many).clusters, 10);
}

// The seed's preference needs the farthest pair; the pruned search must find exactly what all pairs give,
// on clustered samples (where it prunes) and on uniform ones (where it cannot much).
TEST(AffinityPropagation, FarthestPairIsExact)
{
	std::mt19937 rng(5);
	std::uniform_real_distribution<float> uniform(-30.f, 30.f);
	for (const bool clustered : {true, false})
		for (const int n : {2, 3, 50, 400}) {
			cv::Mat samples(n, 6, CV_32F);
			for (int i = 0; i < n; ++i)
				for (int d = 0; d < 6; ++d)
					samples.at<float>(i, d) =
						clustered ? static_cast<float>(10 * (i % 4)) + uniform(rng) / 30
							  : uniform(rng);
			float brute = 0;
			for (int i = 0; i < n; ++i)
				for (int j = i + 1; j < n; ++j)
					brute = std::max(brute,
							 static_cast<float>(cv::norm(samples.row(i), samples.row(j),
										     cv::NORM_L2SQR)));
			AffinityPropagation ap;
			EXPECT_NEAR(ap.farthest_pair(samples.ptr<float>(), static_cast<size_t>(n), 6), brute,
				    brute * 1e-5)
				<< (clustered ? "clustered" : "uniform") << " n=" << n;
		}
}

// Linking k-nearest pairs both ways gives the same clusters on separated blobs, and with every sample
// linked it is the dense algorithm as well.
TEST(AffinityPropagation, SymmetricNeighboursKeepTheAnswer)
{
	const cv::Mat samples = blobs({{0, 0}, {20, 0}, {0, 20}, {30, 30}}, 40);
	AffinityParams params;
	params.symmetric = true;
	AffinityPropagation ap;
	const AffinityResult &result = ap.cluster(samples, params);
	EXPECT_TRUE(result.converged);
	EXPECT_EQ(result.clusters, 4);
	for (size_t b = 0; b < 4; ++b)
		for (size_t i = 0; i < 40; ++i)
			EXPECT_EQ(result.exemplar[b * 40 + i], result.exemplar[b * 40]) << "blob " << b;
	const cv::Mat few = blobs({{0, 0}, {12, 3}, {5, 14}}, 20, 3);
	params.neighbours = few.rows - 1;
	const AffinityResult all = ap.cluster(few, params);
	const AffinityResult dense = affinity_propagation_dense(few, params);
	EXPECT_EQ(all.clusters, dense.clusters);
	EXPECT_EQ(all.exemplar, dense.exemplar);
}

TEST(AffinityPropagation, TrivialSizes)
{
	AffinityPropagation ap;
	EXPECT_EQ(ap.cluster(cv::Mat(0, 3, CV_32F), {}).clusters, 0);
	const cv::Mat one(1, 3, CV_32F, cv::Scalar(1));
	const auto &r = ap.cluster(one, {});
	EXPECT_EQ(r.clusters, 1);
	EXPECT_EQ(r.exemplar, std::vector<int>{0});
}

namespace {

/// A rig like a 640x480 camera's with a 12 cm baseline, for points given depth by at_depth.
geometry::StereoRig test_rig()
{
	geometry::StereoRig rig;
	rig.fx = rig.fy = 900;
	rig.cx = 320;
	rig.cy = 240;
	rig.baseline_m = 0.12;
	return rig;
}

/// Where pixel `px` lies at depth `z` in `rig`'s camera.
cv::Vec3f at_depth(cv::Point2f px, float z, const geometry::StereoRig &rig)
{
	return {static_cast<float>((px.x - rig.cx) * z / rig.fx), static_cast<float>((px.y - rig.cy) * z / rig.fy), z};
}

/// Frames 0.1 s apart, nothing else known (no rig, no pose, no image size).
GroupMotionContext tenth_of_a_second()
{
	GroupMotionContext context;
	context.dt_s = 0.1;
	return context;
}

/// Frames 0.1 s apart through `rig`.
GroupMotionContext through(const geometry::StereoRig &rig)
{
	GroupMotionContext context = tenth_of_a_second();
	context.rig = rig;
	return context;
}

/// The groups of the second of two frames with the same points (a group is published from its second
/// frame on).
GroupOutput second_of_two(const std::vector<MotionPoint> &points, const GroupParams &params,
			  const GroupMotionContext &context)
{
	AffinityPropagation workspace;
	const GroupOutput first = find_groups(points, nullptr, context, params, workspace);
	return find_groups(points, &first.memory, context, params, workspace);
}

/// The same, frames 0.1 s apart without a rig.
GroupOutput second_of_two(const std::vector<MotionPoint> &points, const GroupParams &params)
{
	return second_of_two(points, params, tenth_of_a_second());
}

/// `count` points of a still background spread over a 640x480 frame: what a pose-explained scene leaves,
/// residuals of noise (standard deviation `sigma_px`).
std::vector<MotionPoint> still_background(std::mt19937 &rng, int count = 120, float sigma_px = 0.2F)
{
	std::normal_distribution<float> noise(0.f, sigma_px);
	std::vector<MotionPoint> points;
	for (int i = 0; i < count; ++i) {
		MotionPoint p;
		p.px = {static_cast<float>((i * 37) % 640), static_cast<float>((i * 53) % 480)};
		p.residual = {noise(rng), noise(rng)};
		p.flow = p.residual;
		points.push_back(p);
	}
	return points;
}

/// One frame of a constructed scene: a static background (residual ~0, a little noise) and two groups
/// of 20 points crossing each other, A (rows 200-240) moving right, B (rows 260-300) moving left.
std::vector<MotionPoint> crossing_frame(int frame, std::mt19937 &rng)
{
	std::normal_distribution<float> noise(0.f, 0.2f);
	std::vector<MotionPoint> points = still_background(rng);
	for (int group = 0; group < 2; ++group) {
		const float speed = group == 0 ? 6.f : -6.f;
		const float x0 = group == 0 ? 100.f + speed * static_cast<float>(frame)
					    : 540.f + speed * static_cast<float>(frame);
		const float y0 = group == 0 ? 200.f : 260.f;
		for (int i = 0; i < 20; ++i) {
			MotionPoint p;
			p.px = {x0 + static_cast<float>(i % 5) * 8.f, y0 + static_cast<float>(i / 5) * 10.f};
			p.flow = {speed + noise(rng), noise(rng)};
			p.residual = p.flow;
			points.push_back(p);
		}
	}
	return points;
}

} // namespace

TEST(Groups, IdsSurviveTwoGroupsCrossing)
{
	std::mt19937 rng(5);
	GroupParams params;
	AffinityPropagation workspace;
	GroupMemory memory;
	GroupMotionContext context = tenth_of_a_second();
	int id_a = 0, id_b = 0;
	// 70 frames: A from x=100 to 520, B from 540 to 120; they pass each other around frame 37.
	for (int frame = 0; frame < 70; ++frame) {
		const auto points = crossing_frame(frame, rng);
		GroupOutput out = find_groups(points, frame == 0 ? nullptr : &memory, context, params, workspace);
		memory = out.memory;
		EXPECT_TRUE(out.clustering_ms.has_value()) << "clustered, so timed; frame " << frame;
		if (frame == 0) {
			EXPECT_TRUE(out.groups.empty()) << "published before min_age_frames";
			continue;
		}
		ASSERT_EQ(out.groups.size(), 2u) << "frame " << frame;
		// Which published group is A: the one moving right.
		const auto &a = out.groups[0].image_velocity_pxps[0] > 0 ? out.groups[0] : out.groups[1];
		const auto &b = out.groups[0].image_velocity_pxps[0] > 0 ? out.groups[1] : out.groups[0];
		EXPECT_NEAR(a.image_velocity_pxps[0], 60, 6) << "frame " << frame;
		EXPECT_NEAR(b.image_velocity_pxps[0], -60, 6) << "frame " << frame;
		EXPECT_EQ(a.point_count, 20) << "frame " << frame;
		if (frame == 1) {
			id_a = a.id;
			id_b = b.id;
			EXPECT_NE(id_a, id_b);
		}
		EXPECT_EQ(a.id, id_a) << "frame " << frame;
		EXPECT_EQ(b.id, id_b) << "frame " << frame;
		// No background point is called part of a group.
		for (size_t i = 0; i < 120; ++i)
			EXPECT_EQ(out.group_of_point[i], -1) << "background point " << i << " in frame " << frame;
	}
}

TEST(Groups, WorldVelocityIsARunningMeanThenAnAverage)
{
	// Group A of the crossing scene alone, 5 m away, with a depth that says 1.0 m/s to the right give or take
	// 0.4 m/s, alternating frame by frame (measurement noise); the camera stands still.
	std::mt19937 rng(5);
	GroupParams params;	      // smoothing 0.2: a running mean over the first 5 frames
	params.velocity_window_s = 0; // the averages alone (the positions here do not follow the velocities)
	AffinityPropagation workspace;
	GroupMemory memory;
	GroupMotionContext context = tenth_of_a_second();
	context.curr_from_prev = geometry::Pose{};
	context.world_from_curr = geometry::Pose{};
	for (int frame = 0; frame < 30; ++frame) {
		auto points = crossing_frame(frame, rng);
		points.resize(140);
		const double measured = frame % 2 == 0 ? 0.6 : 1.4;
		for (size_t i = 120; i < points.size(); ++i) {
			const cv::Vec3f now(points[i].px.x / 100, 0, 5);
			points[i].xyz = now;
			points[i].prev_xyz = now - cv::Vec3f(static_cast<float>(measured * context.dt_s), 0, 0);
		}
		GroupOutput out = find_groups(points, frame == 0 ? nullptr : &memory, context, params, workspace);
		memory = out.memory;
		if (frame == 0)
			continue;
		ASSERT_EQ(out.groups.size(), 1u) << "frame " << frame;
		ASSERT_TRUE(out.groups[0].world_velocity_mps.has_value());
		const double vx = (*out.groups[0].world_velocity_mps)[0];
		if (frame == 1) {
			EXPECT_NEAR(vx, (0.6 + 1.4) / 2, 1e-4);
		} else if (frame == 4) {
			EXPECT_NEAR(vx, (0.6 + 1.4 + 0.6 + 1.4 + 0.6) / 5, 1e-4);
		} else if (frame >= 5) {
			// Then the average settles to swing by 0.4 * 0.2 / (2 - 0.2) = 0.044 around 1.0 (0.067 at frame
			// 6, coming from 0.92); with a weight of 0.5 it would swing by 0.13.
			EXPECT_NEAR(vx, 1.0, 0.08) << "frame " << frame;
		}
	}
}

TEST(Groups, VelocityAlongASightLineWeighsTheFittedSlopeAndTheMeasuredMeanByTheirSpread)
{
	// A mover closing along z at 1.5 m/s, seen every 0.1 s for a second; the sight line is z.
	const cv::Vec3d ray(0, 0, 1);
	const auto history = [](double position_noise_m, double measured_mps, double measured_noise_mps) {
		PositionHistory h;
		for (int k = 0; k < 11; ++k) {
			const double sign = k % 2 == 0 ? 1 : -1;
			const double t = 0.1 * k;
			h.push({t, cv::Vec3d(0.2, 0, 9 - 1.5 * t + sign * position_noise_m),
				cv::Vec3d(0, 0, measured_mps + sign * measured_noise_mps)});
		}
		return h;
	};
	// Steady positions (2 cm) and frame-to-frame velocities that swing by 2 m/s: the slope wins.
	const auto steady = velocity_along(history(0.02, -1.5, 2.0), 0.5, ray);
	ASSERT_TRUE(steady.has_value());
	EXPECT_NEAR(steady->value, -1.5, 0.05);
	// Positions that jump by 30 cm and measured velocities of -1.2 give or take 1 cm/s: the mean wins.
	const auto jumpy = velocity_along(history(0.3, -1.2, 0.01), 0.5, ray);
	ASSERT_TRUE(jumpy.has_value());
	EXPECT_NEAR(jumpy->value, -1.2, 0.01);
	// Equal spreads land between the two (both unbiased here, so on the truth).
	const auto both = velocity_along(history(0.05, -1.5, 0.5), 0.5, ray);
	ASSERT_TRUE(both.has_value());
	EXPECT_NEAR(both->value, -1.5, 0.1);
	// Across the sight line both say x stood still, without spread: exact.
	const auto across = velocity_along(history(0.02, -1.5, 2.0), 0.5, cv::Vec3d(1, 0, 0));
	ASSERT_TRUE(across.has_value());
	EXPECT_NEAR(across->value, 0, 1e-9);
	EXPECT_EQ(across->variance, 0);
	// Too short a span (0.2 s of a 0.5 s window), or no window: nothing.
	PositionHistory short_one;
	for (int k = 0; k < 3; ++k)
		short_one.push({0.1 * k, cv::Vec3d(0, 0, 9 - 0.15 * k), cv::Vec3d(0, 0, -1.5)});
	EXPECT_FALSE(velocity_along(short_one, 0.5, ray).has_value());
	EXPECT_FALSE(velocity_along(history(0.02, -1.5, 2.0), 0, ray).has_value());
	// The ring keeps its newest kCapacity entries.
	PositionHistory full;
	for (size_t k = 0; k < PositionHistory::kCapacity + 5; ++k)
		full.push({static_cast<double>(k), cv::Vec3d(0, 0, 0), std::nullopt});
	EXPECT_EQ(full.size, PositionHistory::kCapacity);
	EXPECT_EQ(full.newest(0).t_s, static_cast<double>(PositionHistory::kCapacity + 4));
	EXPECT_EQ(full.newest(PositionHistory::kCapacity - 1).t_s, 5.0);
}

TEST(Groups, VelocityTrendIsTheMeasuredVelocitiesSlope)
{
	// A mover speeding up by 0.6 m/s^2 along z and slowing by 0.2 across (x), its measurements off by
	// alternating errors of 0.05 m/s (which tilt an even count's line by 2 * 0.05 / (n * dt) at most).
	PositionHistory history;
	for (int k = 0; k < 30; ++k) {
		const double t = 0.1 * k;
		const double error = k % 2 == 0 ? 0.05 : -0.05;
		history.push({t, cv::Vec3d(0, 0, 0), cv::Vec3d(1.0 - 0.2 * t + error, 0, 1.3 + 0.6 * t + error)});
	}
	const auto trend = velocity_trend(history, 16);
	ASSERT_TRUE(trend.has_value());
	EXPECT_NEAR(trend->acceleration[0], -0.2, 2 * 0.05 / (16 * 0.1));
	EXPECT_NEAR(trend->acceleration[1], 0.0, 1e-12);
	EXPECT_NEAR(trend->acceleration[2], 0.6, 2 * 0.05 / (16 * 0.1));
	// Each slope's variance from the line's residuals: errors of 0.05 over 16 samples 0.1 s apart
	// (sum of squared times 3.4 s^2): about 0.05^2 / 3.4, none on the axis without errors.
	EXPECT_NEAR(trend->variance[2], 0.05 * 0.05 / 3.4, 0.3 * 0.05 * 0.05 / 3.4);
	EXPECT_NEAR(trend->variance[1], 0.0, 1e-20);
	// The newest only: a turn back 20 frames ago does not count.
	PositionHistory turned = history;
	for (int k = 0; k < 16; ++k)
		turned.push({3.0 + 0.1 * k, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, -1.0)});
	const auto steady = velocity_trend(turned, 16);
	ASSERT_TRUE(steady.has_value());
	EXPECT_NEAR(cv::norm(steady->acceleration), 0.0, 1e-9);
	// Entries without a measurement are skipped; fewer than four measurements or one instant tell no trend.
	PositionHistory sparse;
	for (int k = 0; k < 12; ++k)
		sparse.push({0.1 * k, cv::Vec3d(0, 0, 0),
			     k % 4 == 0 ? std::optional<cv::Vec3d>(cv::Vec3d(0, 0, 0.5 * k)) : std::nullopt});
	EXPECT_FALSE(velocity_trend(sparse, 16).has_value());
	sparse.push({1.2, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 6.0)});
	ASSERT_TRUE(velocity_trend(sparse, 16).has_value());
	EXPECT_NEAR(velocity_trend(sparse, 16)->acceleration[2], 5.0, 1e-9);
	PositionHistory instant;
	for (int k = 0; k < 6; ++k)
		instant.push({1.0, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, k)});
	EXPECT_FALSE(velocity_trend(instant, 16).has_value());
}

TEST(Groups, MeasuredSpreadCountsPersistentErrorsAsFewerMeasurements)
{
	const cv::Vec3d ray(0, 0, 1);
	// Along the sight: errors alternating by 1 m/s (lag-one correlation negative, credited as none); across
	// (x): an error that drifts, a slow sine over 16 frames (strongly persistent, the credit's cap).
	PositionHistory history;
	for (int k = 0; k < 20; ++k)
		history.push({0.1 * k, cv::Vec3d(0, 0, 0),
			      cv::Vec3d(0.3 * std::sin(2 * CV_PI * k / 16.0), 0, -1.5 + (k % 2 == 0 ? 1 : -1))});
	const auto spread = measured_spread(history, 16, ray);
	ASSERT_TRUE(spread.has_value());
	EXPECT_DOUBLE_EQ(spread->along_persistence, 1);
	EXPECT_NEAR(spread->across_persistence, (1 + 0.7) / (1 - 0.7), 1e-9);
	// Sample variances (16 alternating values of +-1: 16/15), Student-widened by 15/13; across, x's over
	// the two axes normal to the sight.
	EXPECT_NEAR(spread->along, 16.0 / 15 * 15.0 / 13, 1e-9);
	EXPECT_GT(spread->across, 0.3 * 0.3 / 2 / 2 * 0.9);
	// The newest measurements only, and at least four of them.
	EXPECT_FALSE(measured_spread(history, 3, ray).has_value());
	PositionHistory none;
	for (int k = 0; k < 8; ++k)
		none.push({0.1 * k, cv::Vec3d(0, 0, 0), std::nullopt});
	EXPECT_FALSE(measured_spread(none, 16, ray).has_value());
}

namespace {

/// Group A of the crossing scene, but straight ahead and closing along z from 9 m at 1.5 m/s: its members'
/// depth changes from one frame to the next say 1.5 m/s give or take 2 m/s (the disparity's noise at that
/// range), alternating, and their x changes swing by `across_swing_mps` the same way, while their median
/// position follows the truth within 2 cm. Per frame: the single group published with a speed, if any.
std::vector<std::optional<TargetGroup>> closing_mover(double window_s, double across_swing_mps,
						      bool anchored_velocity = false)
{
	std::mt19937 rng(5);
	GroupParams params;
	params.velocity_window_s = window_s;
	params.anchored_velocity = anchored_velocity;
	AffinityPropagation workspace;
	GroupMemory memory;
	GroupMotionContext context = tenth_of_a_second();
	context.curr_from_prev = geometry::Pose{};
	context.world_from_curr = geometry::Pose{};
	std::vector<std::optional<TargetGroup>> published;
	for (int frame = 0; frame < 30; ++frame) {
		auto points = crossing_frame(frame, rng);
		points.resize(140);
		const double sign = frame % 2 == 0 ? 1 : -1;
		const double z = 9 - 1.5 * 0.1 * frame + 0.02 * sign, measured = -1.5 + 2.0 * sign;
		for (size_t i = 120; i < points.size(); ++i) {
			const cv::Vec3f now(0.01F * (static_cast<float>(i) - 130), 0, static_cast<float>(z));
			points[i].xyz = now;
			points[i].prev_xyz = now - cv::Vec3f(static_cast<float>(across_swing_mps * sign * context.dt_s),
							     0, static_cast<float>(measured * context.dt_s));
			// Each member's track began 0.5 s before (its anchor there, give or take 3 cm by member).
			const float jitter = 0.03F * static_cast<float>(static_cast<int>(i % 3) - 1);
			points[i].anchor_world =
				cv::Vec3f(now[0], 0, static_cast<float>(9 - 1.5 * (0.1 * frame - 0.5)) + jitter);
			points[i].anchor_span_s = 0.5;
		}
		GroupOutput out = find_groups(points, frame == 0 ? nullptr : &memory, context, params, workspace);
		memory = out.memory;
		published.push_back(out.groups.size() == 1 && out.groups[0].speed_mps
					    ? std::optional<TargetGroup>(out.groups[0])
					    : std::nullopt);
	}
	return published;
}

} // namespace

TEST(Groups, AMoverAlongTheSightLineTakesItsSpeedFromItsPositions)
{
	// Its speed from frame 10 on.
	const auto speeds = [](double window_s) {
		std::vector<double> out;
		const auto published = closing_mover(window_s, 0);
		for (size_t frame = 10; frame < published.size(); ++frame)
			if (published[frame])
				out.push_back(*published[frame]->speed_mps);
		return out;
	};
	const auto fitted = speeds(0.5);
	ASSERT_EQ(fitted.size(), 20U);
	for (const double speed : fitted)
		EXPECT_NEAR(speed, 1.5, 0.1);
	// The averages alone swing by 2.0 * 0.2 / 1.8 = 0.22 m/s about the truth.
	const auto averaged = speeds(0);
	ASSERT_EQ(averaged.size(), 20U);
	EXPECT_GT(*std::max_element(averaged.begin(), averaged.end()) -
			  *std::min_element(averaged.begin(), averaged.end()),
		  0.3);
}

TEST(Groups, AYoungGroupsSpeedAlongTheSightAlsoComesFromItsMembersAnchors)
{
	// The closing mover before its positions fill half the 0.5 s window: its speed is the running mean of
	// frame-to-frame changes swinging by 2 m/s, unless its members' anchors (0.5 s back) speak too.
	const auto young_errors = [](bool anchored) {
		std::vector<double> errors;
		for (const auto &g : closing_mover(0.5, 0, anchored))
			if (g && g->age_frames < 6)
				errors.push_back(std::abs(*g->speed_mps - 1.5));
		return errors;
	};
	const auto without = young_errors(false), with = young_errors(true);
	ASSERT_GE(without.size(), 3U);
	ASSERT_EQ(with.size(), without.size());
	EXPECT_GT(*std::max_element(without.begin(), without.end()), 0.4);
	for (const double error : with)
		EXPECT_LT(error, 0.2);
}

TEST(Groups, AGroupsVelocityComesWithItsUncertainty)
{
	// The closing mover with its x measurements swinging by 0.2 m/s: published with the spreads of its
	// estimates along and across the sight line, and of its speed.
	const auto published_groups = [](double window_s) {
		std::vector<TargetGroup> groups;
		for (const auto &g : closing_mover(window_s, 0.2))
			if (g)
				groups.push_back(*g);
		return groups;
	};
	// From the averages alone: the along-sight sample spread (2.0 m/s, a little more over few samples) over
	// the frames averaged, up to (2 - 0.2) / 0.2 = 9 of them; across, a tenth of it.
	const auto averaged = published_groups(0);
	ASSERT_GE(averaged.size(), 25U);
	for (const auto &g : averaged) {
		// Three measurements tell no spread.
		if (g.age_frames < 4) {
			EXPECT_FALSE(g.velocity_sigma_mps.has_value());
			continue;
		}
		ASSERT_TRUE(g.velocity_sigma_mps.has_value()) << "age " << g.age_frames;
		ASSERT_TRUE(g.speed_sigma_mps.has_value());
		// The sample spread of n measurements swinging by 2 m/s, widened by Student's t for n - 1 degrees of
		// freedom, over the frames averaged; the swings alternate, so no persistence widens it further.
		const double n = std::min(g.age_frames, 16);
		const double spread = 2.0 * std::sqrt(n / (n - 1)) * std::sqrt((n - 1) / (n - 3));
		const double frames = std::min(g.age_frames, 9);
		EXPECT_NEAR((*g.velocity_sigma_mps)[0], spread / std::sqrt(frames), 0.05) << "age " << g.age_frames;
		EXPECT_NEAR((*g.velocity_sigma_mps)[1] / (*g.velocity_sigma_mps)[0], 0.1 / std::sqrt(2.0), 0.03);
		// Moving along the sight, the speed's spread is that along it.
		EXPECT_NEAR(*g.speed_sigma_mps, (*g.velocity_sigma_mps)[0], 0.05);
	}
	// Younger is less sure: 2.0 m/s at 4 frames, 0.74 from 16 on.
	const auto first = std::find_if(averaged.begin(), averaged.end(),
					[](const TargetGroup &g) { return g.velocity_sigma_mps.has_value(); });
	ASSERT_NE(first, averaged.end());
	EXPECT_GT((*first->velocity_sigma_mps)[0], 2.5 * (*averaged.back().velocity_sigma_mps)[0]);
	// Once the positions fill half the window, the fitted line's spread: a few cm/s.
	const auto fitted = published_groups(0.5);
	ASSERT_GE(fitted.size(), 25U);
	for (const auto &g : fitted)
		if (g.age_frames >= 10) {
			EXPECT_LT((*g.velocity_sigma_mps)[0], 0.1) << "age " << g.age_frames;
			EXPECT_LT(std::abs(*g.speed_mps - 1.5), 3 * *g.speed_sigma_mps + 0.02)
				<< "age " << g.age_frames;
		}
}

TEST(Groups, AnAcceleratingMoversSpeedSigmaCoversTheAveragesLag)
{
	// A mover receding along the sight and speeding up by 1 m/s^2 (0.5 m/s at the start), its frame-to-frame
	// measurements off by alternating errors of 0.05 m/s: the averages describe it as it was about a quarter
	// of a second ago, some 0.25 m/s slow, while their spread alone says a few cm/s.
	std::mt19937 rng(5);
	GroupParams params;
	AffinityPropagation workspace;
	GroupMemory memory;
	GroupMotionContext context = tenth_of_a_second();
	context.curr_from_prev = geometry::Pose{};
	context.world_from_curr = geometry::Pose{};
	const auto z_at = [](double t) { return 5 + 0.5 * t + 0.5 * t * t; };
	int judged = 0, covered = 0;
	for (int frame = 0; frame < 30; ++frame) {
		auto points = crossing_frame(frame, rng);
		points.resize(140);
		const double t = 0.1 * frame;
		const double error = frame % 2 == 0 ? 0.05 : -0.05;
		const double step = z_at(t) - z_at(t - context.dt_s) + error * context.dt_s;
		for (size_t i = 120; i < points.size(); ++i) {
			const cv::Vec3f now(0.01F * (static_cast<float>(i) - 130), 0, static_cast<float>(z_at(t)));
			points[i].xyz = now;
			points[i].prev_xyz = now - cv::Vec3f(0, 0, static_cast<float>(step));
		}
		GroupOutput out = find_groups(points, frame == 0 ? nullptr : &memory, context, params, workspace);
		memory = out.memory;
		if (out.groups.size() != 1 || !out.groups[0].speed_mps || out.groups[0].age_frames < 10)
			continue;
		const TargetGroup &g = out.groups[0];
		ASSERT_TRUE(g.speed_sigma_mps.has_value());
		const double truth = 0.5 + t;
		const double miss = std::abs(*g.speed_mps - truth);
		EXPECT_GT(miss, 0.1) << "frame " << frame << ": the lag is there to cover";
		++judged;
		covered += miss <= 2 * *g.speed_sigma_mps;
	}
	ASSERT_GE(judged, 15);
	EXPECT_GE(covered, judged * 9 / 10);
}

TEST(Groups, AFarMoverHiddenByANearOneComesOutUnderItsId)
{
	// A far mover (20 points, 8 m, 3 px a frame to the left) and a near one (60 points over 120 x 200 px, 3 m,
	// 8 px a frame to the right) pass each other; the far one's points inside the near one's extent are
	// hidden: from frame 16 on, all of them from frame 20 to 27.
	const auto far_and_near_ids = [](int occlusion_frames) {
		std::mt19937 rng(5);
		std::normal_distribution<float> noise(0.f, 0.2f);
		GroupParams params;
		params.occlusion_frames = occlusion_frames;
		AffinityPropagation workspace;
		GroupMemory memory;
		const GroupMotionContext context = tenth_of_a_second();
		std::vector<std::pair<int, int>> ids; // per frame: the far group's id (0: none), the near one's
		for (int frame = 0; frame < 45; ++frame) {
			std::vector<MotionPoint> points = still_background(rng);
			const float near_x0 = 100.F + 8.F * static_cast<float>(frame), near_x1 = near_x0 + 120.F;
			const size_t near_first = points.size();
			for (int i = 0; i < 60; ++i) {
				MotionPoint p;
				p.px = {near_x0 + static_cast<float>(i % 6) * 24.F,
					150.F + static_cast<float>(i / 6) * 20.F};
				p.flow = {8.F + noise(rng), noise(rng)};
				p.residual = p.flow;
				p.xyz = cv::Vec3f(0, 0, 3);
				points.push_back(p);
			}
			const size_t far_first = points.size();
			for (int i = 0; i < 20; ++i) {
				MotionPoint p;
				p.px = {400.F - 3.F * static_cast<float>(frame) + static_cast<float>(i % 5) * 10.F,
					250.F + static_cast<float>(i / 5) * 10.F};
				if (p.px.x >= near_x0 - 4 && p.px.x <= near_x1 + 4)
					continue; // behind the near mover
				p.flow = {-3.F + noise(rng), noise(rng)};
				p.residual = p.flow;
				p.xyz = cv::Vec3f(0, 0, 8);
				points.push_back(p);
			}
			GroupOutput out =
				find_groups(points, frame == 0 ? nullptr : &memory, context, params, workspace);
			memory = out.memory;
			const auto id_of = [&](size_t i) {
				return i < points.size() && out.group_of_point[i] >= 0
					       ? out.groups[static_cast<size_t>(out.group_of_point[i])].id
					       : 0;
			};
			ids.emplace_back(points.size() > far_first ? id_of(far_first) : 0, id_of(near_first));
		}
		return ids;
	};
	const auto ids = far_and_near_ids(30);
	const int far_id = ids[10].first, near_id = ids[10].second;
	ASSERT_NE(far_id, 0);
	ASSERT_NE(near_id, 0);
	ASSERT_NE(far_id, near_id);
	for (int frame = 1; frame < 45; ++frame)
		EXPECT_EQ(ids[static_cast<size_t>(frame)].second, near_id) << "the near mover, frame " << frame;
	for (int frame = 20; frame <= 27; ++frame)
		EXPECT_EQ(ids[static_cast<size_t>(frame)].first, 0) << "hidden, frame " << frame;
	for (int frame = 31; frame < 45; ++frame)
		EXPECT_EQ(ids[static_cast<size_t>(frame)].first, far_id) << "come out, frame " << frame;
	// Forgotten after max_missed_frames, it comes out under a new id.
	const auto forgotten = far_and_near_ids(0);
	EXPECT_NE(forgotten[40].first, 0);
	EXPECT_NE(forgotten[40].first, forgotten[10].first);
}

TEST(Groups, AMissedGroupCoastsOnItsVelocityKeepingItsId)
{
	// Group A of the crossing scene alone (B's points dropped), seen for 6 frames, then missing from the
	// points for 3 frames, then seen again.
	std::mt19937 rng(5);
	GroupParams params; // coast_frames 2, max_missed_frames 3
	AffinityPropagation workspace;
	GroupMemory memory;
	GroupMotionContext context = tenth_of_a_second();
	int id = 0;
	std::array<float, 4> last_box{};
	for (int frame = 0; frame < 11; ++frame) {
		auto points = crossing_frame(frame, rng);
		points.resize(140); // background and A
		const bool missing = frame >= 6 && frame <= 8;
		if (missing)
			points.resize(120);
		GroupOutput out = find_groups(points, frame == 0 ? nullptr : &memory, context, params, workspace);
		memory = out.memory;
		if (frame == 0)
			continue;
		const int missed = missing ? frame - 5 : 0;
		if (missed > params.coast_frames) {
			EXPECT_TRUE(out.groups.empty()) << "coasted past coast_frames, frame " << frame;
			continue;
		}
		ASSERT_EQ(out.groups.size(), 1u) << "frame " << frame;
		const TargetGroup &g = out.groups[0];
		if (frame == 1)
			id = g.id;
		EXPECT_EQ(g.id, id) << "frame " << frame;
		EXPECT_EQ(g.missed_frames, missed) << "frame " << frame;
		if (missed > 0) {
			// Where its 60 px/s take it: 6 px per missed frame from the last box it was found with.
			EXPECT_EQ(g.point_count, 0);
			EXPECT_NEAR(g.box_px[0] - last_box[0], 6.f * static_cast<float>(missed), 1.5f);
			EXPECT_NEAR(g.box_px[1], last_box[1], 0.5f);
			// No background point joins a coasted group that moves unlike it.
			for (size_t i = 0; i < 120; ++i)
				EXPECT_EQ(out.group_of_point[i], -1) << "frame " << frame;
		} else {
			EXPECT_EQ(g.point_count, 20) << "frame " << frame;
			last_box = g.box_px;
		}
	}
}

TEST(Groups, AGroupLeavingThroughTheEdgeBandCoastsOutOfView)
{
	// A group of 20 points moving right at 6 px a frame towards the right edge of a 640 x 480 image, whose
	// points vanish once past x = 600 (the detector's blind band along the edge). With the image's size
	// known, its track is published on, coasted, until its centre leaves the image, with one id, its box
	// clipped to the image; without it, only coast_frames (2) frames.
	for (const bool size_known : {true, false}) {
		std::mt19937 rng(3);
		std::normal_distribution<float> noise(0.F, 0.2F);
		GroupParams params; // edge_band_px 40, edge_coast_frames 15
		AffinityPropagation workspace;
		GroupMemory memory;
		GroupMotionContext context = tenth_of_a_second();
		if (size_known)
			context.image_size = {640, 480};
		int id = 0, last_seen = -1, coasted = 0;
		for (int frame = 0; frame < 40; ++frame) {
			auto points = still_background(rng);
			const float x0 = 500.F + 6.F * static_cast<float>(frame);
			for (int i = 0; i < 20; ++i) {
				MotionPoint p;
				p.px = {x0 + static_cast<float>(i % 5) * 8.F, 200.F + static_cast<float>(i / 5) * 10.F};
				p.residual = p.flow = {6.F + noise(rng), noise(rng)};
				if (p.px.x <= 600.F)
					points.push_back(p);
			}
			const GroupOutput out =
				find_groups(points, frame == 0 ? nullptr : &memory, context, params, workspace);
			memory = out.memory;
			if (frame == 0)
				continue;
			if (out.groups.empty())
				break;
			ASSERT_EQ(out.groups.size(), 1u) << "frame " << frame;
			const TargetGroup &g = out.groups[0];
			if (id == 0)
				id = g.id;
			EXPECT_EQ(g.id, id) << "frame " << frame;
			EXPECT_LE(g.box_px[2], 640.F) << "frame " << frame;
			last_seen = frame;
			coasted += g.missed_frames > 0 ? 1 : 0;
		}
		// The last points vanish at frame 17 (x0 = 602); the group's centre (x0 + 16 px) leaves the image
		// at x0 = 624, frame 21, and it is coasted from the frame its cluster falls under min_points
		// (measured: seen to frame 22, 7 of those frames coasted; without the size, to frame 17, 2).
		if (size_known) {
			EXPECT_GE(last_seen, 20);
			EXPECT_LE(last_seen, 23);
			EXPECT_GE(coasted, 4);
		} else {
			EXPECT_LE(coasted, params.coast_frames);
			EXPECT_LE(last_seen, 18);
		}
	}
}

TEST(Groups, AMoverSeenFirstInPartThenWholeKeepsItsId)
{
	// A mover 160 x 200 px moving 6 px per frame to the right: for three frames only a 40 x 40 px piece in
	// its top-left corner shows motion (a weakly textured mover), then all of it. The whole one's centre lies
	// ~100 px from where the piece's was predicted, beyond the gate (60 px, or half the piece's diagonal),
	// but its box holds the piece's predicted box and it moves alike: the same mover, the same id. A cluster
	// that moves otherwise over the same place does not take the id.
	for (const float whole_speed : {6.F, -6.F}) {
		std::mt19937 rng(9);
		std::normal_distribution<float> noise(0.f, 0.2f);
		GroupParams params;
		params.affinity.neighbours = 1000; // one cluster for the whole mover
		params.affinity.preference_scale = 2;
		AffinityPropagation workspace;
		GroupMemory memory;
		GroupMotionContext context = tenth_of_a_second();
		int id = 0;
		for (int frame = 0; frame < 6; ++frame) {
			const bool whole = frame >= 3;
			const float speed = whole ? whole_speed : 6.F;
			const float x0 = 100.F + 6.F * static_cast<float>(frame), y0 = 100.F;
			std::vector<MotionPoint> points = still_background(rng);
			const int step = whole ? 20 : 10, columns = whole ? 9 : 5, rows = whole ? 11 : 5;
			for (int r = 0; r < rows; ++r)
				for (int c = 0; c < columns; ++c) {
					MotionPoint p;
					p.px = {x0 + static_cast<float>(c * step), y0 + static_cast<float>(r * step)};
					p.flow = {speed + noise(rng), noise(rng)};
					p.residual = p.flow;
					points.push_back(p);
				}
			GroupOutput out =
				find_groups(points, frame == 0 ? nullptr : &memory, context, params, workspace);
			memory = out.memory;
			if (frame == 0)
				continue;
			const auto found = std::find_if(out.groups.begin(), out.groups.end(),
							[](const TargetGroup &g) { return g.missed_frames == 0; });
			if (whole && whole_speed < 0) {
				// Moving the other way: not the piece's mover; its id is only on the piece's coasted
				// box.
				for (const TargetGroup &g : out.groups)
					if (g.id == id) {
						EXPECT_GT(g.missed_frames, 0) << "frame " << frame;
					}
				continue;
			}
			ASSERT_NE(found, out.groups.end()) << "frame " << frame;
			EXPECT_EQ(found->point_count, rows * columns) << "frame " << frame;
			if (frame == 1)
				id = found->id;
			EXPECT_EQ(found->id, id) << "frame " << frame;
		}
	}
}

TEST(Groups, TwoTracksOnOneMoverEndAsOne)
{
	// A monocular walker moving 6 px per frame to the right whose points show first as two pieces 70 px
	// apart (head and legs; the cut at split_gap_px makes each a group with its own track), then whole. The
	// whole cluster continues one track; the other track's predicted box lies on it and moves alike, so that
	// track ends: one group on the walker, not the whole one and the other piece coasting beside it. A
	// cluster moving the other way over the same place does not end it.
	for (const float whole_speed : {6.F, -6.F}) {
		std::mt19937 rng(3);
		std::normal_distribution<float> noise(0.f, 0.2f);
		GroupParams params;
		AffinityPropagation workspace;
		GroupMemory memory;
		GroupMotionContext context = tenth_of_a_second();
		std::set<int> piece_ids;
		for (int frame = 0; frame < 8; ++frame) {
			const bool whole = frame >= 4;
			const float speed = whole ? whole_speed : 6.F;
			const float x0 = 200.F + 6.F * static_cast<float>(frame);
			std::vector<MotionPoint> points = still_background(rng);
			for (int row = 0; row < 12; ++row) {
				const bool gap = row >= 4 && row < 8; // rows 140-170: the pieces' gap, 70 px
				if (gap && !whole)
					continue;
				for (int column = 0; column < 4; ++column) {
					MotionPoint p;
					p.px = {x0 + static_cast<float>(column * 10),
						100.F + static_cast<float>(row * 10)};
					p.residual = p.flow = {speed + noise(rng), noise(rng)};
					points.push_back(p);
				}
			}
			GroupOutput out =
				find_groups(points, frame == 0 ? nullptr : &memory, context, params, workspace);
			memory = out.memory;
			if (frame == 0)
				continue;
			const std::string label =
				"speed " + std::to_string(whole_speed) + ", frame " + std::to_string(frame);
			if (!whole) {
				ASSERT_EQ(out.groups.size(), 2u) << label;
				for (const TargetGroup &g : out.groups)
					piece_ids.insert(g.id);
				continue;
			}
			ASSERT_EQ(piece_ids.size(), 2u) << label;
			if (whole_speed > 0) {
				ASSERT_EQ(out.groups.size(), 1u) << label;
				EXPECT_EQ(out.groups[0].point_count, 48) << label;
				EXPECT_TRUE(piece_ids.contains(out.groups[0].id)) << label;
			} else if (frame - 3 <= params.coast_frames) {
				// Unlike in motion: the nearer track takes the cluster by distance, as any track does,
				// and the other piece is not ended by it but coasts beside it.
				const auto coasting =
					std::count_if(out.groups.begin(), out.groups.end(), [&](const TargetGroup &g) {
						return g.missed_frames > 0 && piece_ids.contains(g.id);
					});
				EXPECT_EQ(coasting, 1) << label;
			}
		}
	}
}

TEST(Groups, ANoiseGroupSeenBrieflyDoesNotCoast)
{
	// Published at its first publishable age (min_age_frames) and then gone: it is not carried on.
	std::mt19937 rng(5);
	GroupParams params;
	AffinityPropagation workspace;
	GroupMemory memory;
	GroupMotionContext context = tenth_of_a_second();
	for (int frame = 0; frame < 4; ++frame) {
		auto points = crossing_frame(frame, rng);
		points.resize(frame < params.min_age_frames ? 140 : 120);
		GroupOutput out = find_groups(points, frame == 0 ? nullptr : &memory, context, params, workspace);
		memory = out.memory;
		EXPECT_EQ(out.groups.size(), frame == params.min_age_frames - 1 ? 1u : 0u) << "frame " << frame;
	}
}

TEST(Groups, ASlowMoverIsFoundWhereTheSceneIsQuiet)
{
	// A walker of 20 points moving 0.6 px per frame (a slow walker far off, as on a fixed camera's footage)
	// among 300 still points whose residuals are noise. Under the fixed floor of 1 px it is not strong
	// motion. Where the noise is 0.04 px (a fixed camera, vtest: 0.04), the floor falls to
	// max(min_flow_floor_px, noise_sigmas x 0.04) = 0.5 px and the walker is a group; where it is 0.3 px (a
	// moving camera's parallax) the floor stays at 1 px and nothing is a group, the noise points included.
	for (const float sigma : {0.04F, 0.3F})
		for (const double sigmas : {0.0, 8.0}) {
			std::mt19937 rng(11);
			std::normal_distribution<float> noise(0.F, sigma);
			GroupParams params;
			params.noise_sigmas = sigmas;
			params.min_flow_floor_px = 0.5;
			params.members = GroupMembers::Flow;
			AffinityPropagation workspace;
			GroupMemory memory;
			const std::string label =
				"noise " + std::to_string(sigma) + ", sigmas " + std::to_string(sigmas);
			for (int frame = 0; frame < 3; ++frame) {
				std::vector<MotionPoint> points = still_background(rng, 300, sigma);
				for (int i = 0; i < 20; ++i) {
					MotionPoint p;
					p.px = {300.F + static_cast<float>(i % 4) * 6.F,
						200.F + static_cast<float>(i / 4) * 10.F};
					p.residual = p.flow = {0.6F + noise(rng), noise(rng)};
					points.push_back(p);
				}
				const GroupOutput out = find_groups(points, frame == 0 ? nullptr : &memory,
								    tenth_of_a_second(), params, workspace);
				memory = out.memory;
				if (frame == 0)
					continue;
				if (sigma < 0.1F && sigmas > 0) {
					ASSERT_EQ(out.groups.size(), 1u) << label;
					EXPECT_GE(out.groups[0].point_count, 18) << label;
					EXPECT_NEAR(out.groups[0].image_velocity_pxps[0], 6.0, 1.0) << label;
				} else {
					EXPECT_TRUE(out.groups.empty()) << label;
				}
			}
		}
}

TEST(Groups, AWalkersFeaturePointsOffByAPyramidStepStayInItsGroup)
{
	// A slow walker of 20 feature points moving 1.2 px a frame, as keypoints report it: positions quantised
	// to their pyramid level, so every other point's residual is 1.5 px off the walker's (a quarter ahead,
	// a quarter behind, the latter under the strong-motion floor and out of the clustering). With the
	// feature points' tolerance (2 px) the walker is one group of its 15 strong points. At 1 px, the dense
	// cells' tolerance, the points ahead leave their cluster and come out as a group of their own.
	for (const double tolerance : {2.0, 1.0}) {
		std::mt19937 rng(3);
		GroupParams params;
		params.point_tolerance_px = tolerance;
		params.members = GroupMembers::Flow;
		AffinityPropagation workspace;
		GroupMemory memory;
		GroupOutput out;
		for (int frame = 0; frame < 3; ++frame) {
			std::vector<MotionPoint> points = still_background(rng, 200, 0.1F);
			for (int i = 0; i < 20; ++i) {
				MotionPoint p;
				p.px = {300.F + static_cast<float>(i % 4) * 6.F,
					200.F + static_cast<float>(i / 4) * 10.F};
				const float off = i % 4 == 1 ? 1.5F : i % 4 == 3 ? -1.5F : 0.F;
				p.residual = p.flow = {1.2F + off, 0.F};
				points.push_back(p);
			}
			out = find_groups(points, frame == 0 ? nullptr : &memory, tenth_of_a_second(), params,
					  workspace);
			memory = out.memory;
		}
		const bool whole = out.groups.size() == 1 && out.groups[0].point_count == 15;
		EXPECT_EQ(whole, tolerance > 1.5)
			<< "tolerance " << tolerance << ": " << out.groups.size() << " groups";
	}
}

TEST(Groups, StillSceneHasNoGroup)
{
	std::mt19937 rng(9);
	std::normal_distribution<float> noise(0.f, 0.3f);
	std::vector<MotionPoint> points(300);
	for (size_t i = 0; i < points.size(); ++i) {
		points[i].px = {static_cast<float>((i * 37) % 640), static_cast<float>((i * 53) % 480)};
		points[i].residual = {noise(rng), noise(rng)}; // what a pose-explained scene leaves: noise
	}
	AffinityPropagation workspace;
	GroupMemory memory;
	for (int frame = 0; frame < 5; ++frame) {
		const GroupOutput out =
			find_groups(points, frame == 0 ? nullptr : &memory, tenth_of_a_second(), {}, workspace);
		memory = out.memory;
		EXPECT_TRUE(out.groups.empty());
		// sigma 0.3 px: one point in ~250 is 1 px off by chance; alone it makes no group
		EXPECT_LE(out.strong.size(), 4u) << "noise under min_flow_px is not strong motion";
	}
	// Nothing to cluster: no clustering time is reported (rather than a 0 that reads as a fast clustering).
	EXPECT_FALSE(find_groups({}, nullptr, tenth_of_a_second(), {}, workspace).clustering_ms.has_value());
}

TEST(Groups, LabelMembersAreTheDynamicPointsWithAResidual)
{
	// Three points: a large residual labelled static (flow's split would take it), a small one labelled
	// dynamic, and a dynamic one without a prediction (NaN residual). Labels take only the second.
	std::vector<MotionPoint> points(3);
	points[0].residual = {8, 0};
	points[1].residual = {0.5F, 0.2F};
	points[1].dynamic = true;
	points[2].residual = {NAN, NAN};
	points[2].dynamic = true;
	GroupParams params;
	params.members = GroupMembers::Labels;
	EXPECT_EQ(strong_motion(points, params), std::vector<uint32_t>{1});
	params.members = GroupMembers::Flow;
	EXPECT_EQ(strong_motion(points, params), std::vector<uint32_t>{0});
}

TEST(Groups, AGroupThatMovedOnlyAlongItsEdgesIsDropped)
{
	// The crossing scene's two groups, both moving sideways. Group A's points are put on horizontal edges
	// (across is up and down: their sideways motion is along the edge, not measured) in share `on_edge` of
	// them; B's stay textured. Most of A on edges: A is the aperture problem's and is dropped, B stays. A
	// minority on edges, or edges across the motion (vertical ones), keep A.
	const auto groups_after = [](double on_edge, cv::Point2f across) {
		std::mt19937 rng(5);
		GroupParams params;
		AffinityPropagation workspace;
		GroupMemory memory;
		GroupMotionContext context = tenth_of_a_second();
		std::vector<TargetGroup> groups;
		for (int frame = 0; frame < 4; ++frame) {
			auto points = crossing_frame(frame, rng);
			for (size_t i = 0; i < 20; ++i)
				if (static_cast<double>(i) < on_edge * 20)
					points[120 + i].across = across;
			GroupOutput out =
				find_groups(points, frame == 0 ? nullptr : &memory, context, params, workspace);
			memory = out.memory;
			groups = out.groups;
		}
		return groups;
	};
	const auto rightwards = [](const std::vector<TargetGroup> &groups) {
		return std::count_if(groups.begin(), groups.end(),
				     [](const TargetGroup &g) { return g.image_velocity_pxps[0] > 0; });
	};
	const std::vector<TargetGroup> none_on_edge = groups_after(0, {0, 1});
	EXPECT_EQ(none_on_edge.size(), 2u);
	EXPECT_EQ(rightwards(none_on_edge), 1);
	const std::vector<TargetGroup> most_on_edge = groups_after(0.6, {0, 1});
	ASSERT_EQ(most_on_edge.size(), 1u) << "A, on edges it slid along, is dropped";
	EXPECT_LT(most_on_edge[0].image_velocity_pxps[0], 0) << "the one left is B";
	EXPECT_EQ(groups_after(0.4, {0, 1}).size(), 2u) << "a minority on edges keeps A";
	EXPECT_EQ(groups_after(1, {1, 0}).size(), 2u) << "edges across the motion measure it";
}

TEST(Groups, PiecesOfANearMoverAtOneDepthAreOneGroup)
{
	// Two pieces of one near mover, 12 feature points each, moving alike 5 px per frame, `gap` px apart: too
	// far for the seed's samples (position scale 40 px) to fall in one cluster or for the boxes to touch. With
	// depth they are one group when they lie at one depth and the gap is within merge_reach_m (1 m) there
	// (fx 900: 300 px at 3 m); two when the depths differ (3 m and 5 m), without depth, or 1.5 m apart.
	struct Case {
		float gap;
		float depth_b; // piece B's depth; A's is 3 m; 0: no depth anywhere
		double reach_m;
		size_t groups;
	};
	const geometry::StereoRig rig = test_rig();
	for (const Case c : {Case{150, 3, 1.0, 1}, Case{150, 5, 1.0, 2}, Case{150, 0, 1.0, 2}, Case{450, 3, 1.0, 2},
			     Case{150, 3, 0.0, 2}}) {
		GroupParams params;
		params.members = GroupMembers::Labels;
		params.merge_reach_m = c.reach_m;
		const GroupMotionContext context = through(rig);
		AffinityPropagation workspace;
		std::vector<MotionPoint> points;
		for (int piece = 0; piece < 2; ++piece)
			for (int i = 0; i < 12; ++i) {
				MotionPoint p;
				const float x0 = piece == 0 ? 20.F : 20.F + 30.F + c.gap;
				p.px = {x0 + static_cast<float>(i % 3) * 15.F,
					150.F + static_cast<float>(i / 3) * 30.F};
				p.flow = p.residual = {5.F, 0.F};
				p.dynamic = true;
				const float z = piece == 0 ? 3.F : c.depth_b;
				if (c.depth_b > 0)
					p.xyz = at_depth(p.px, z, rig);
				points.push_back(p);
			}
		const GroupOutput first = find_groups(points, nullptr, context, params, workspace);
		for (auto &p : points)
			p.px.x += 5.F;
		const GroupOutput out = find_groups(points, &first.memory, context, params, workspace);
		EXPECT_EQ(out.groups.size(), c.groups)
			<< "gap " << c.gap << " px, depth " << c.depth_b << " m, reach " << c.reach_m << " m";
	}
}

TEST(Groups, PiecesOfAMoverComingCloserAreOneGroup)
{
	// A mover 3 m away comes at the camera while drifting right: its image spreads out from the image
	// centre by k = 2 % of each point's offset a frame. Its chest (rows 170-230) and its feet (rows
	// 420-480, below the centre row 240) are two pieces whose residuals differ by 5 px, more than two parts
	// of a mover moving alike may; merge_looming allows for the spreading. Two movers side by side at one
	// depth going apart, whose residuals differ the same way along the row, stay two: spreading cannot be
	// told from going apart there (these two do exactly as one spreading mover's pieces would). Nor are
	// pieces at different depths joined.
	struct Case {
		bool stacked;  // the pieces above one another (else side by side)
		float depth_b; // piece B's depth; A's is 3 m
		double looming;
		size_t groups;
	};
	const geometry::StereoRig rig = test_rig();
	for (const Case c :
	     {Case{true, 3, 0.03, 1}, Case{true, 3, 0.0, 2}, Case{true, 5, 0.03, 2}, Case{false, 3, 0.03, 2}}) {
		GroupParams params;
		params.members = GroupMembers::Labels;
		params.merge_looming = c.looming;
		const GroupMotionContext context = through(rig);
		AffinityPropagation workspace;
		const cv::Point2f centre(static_cast<float>(rig.cx), static_cast<float>(rig.cy));
		const auto frame = [&](int step) {
			std::vector<MotionPoint> points;
			for (int piece = 0; piece < 2; ++piece)
				for (int i = 0; i < 12; ++i) {
					MotionPoint p;
					const cv::Point2f corner =
						c.stacked ? cv::Point2f(300.F, piece == 0 ? 170.F : 420.F)
							  : cv::Point2f(piece == 0 ? 80.F : 380.F,
									piece == 0 ? 170.F : 190.F);
					p.px = corner + cv::Point2f(static_cast<float>(i % 3) * 15.F,
								    static_cast<float>(i / 3) * 20.F);
					p.flow = p.residual = cv::Point2f(2.F, 0.F) + 0.02F * (p.px - centre);
					p.px += static_cast<float>(step) * p.residual;
					p.dynamic = true;
					p.xyz = at_depth(p.px, piece == 0 ? 3.F : c.depth_b, rig);
					points.push_back(p);
				}
			return points;
		};
		const GroupOutput first = find_groups(frame(0), nullptr, context, params, workspace);
		const GroupOutput out = find_groups(frame(1), &first.memory, context, params, workspace);
		EXPECT_EQ(out.groups.size(), c.groups) << (c.stacked ? "stacked" : "side by side") << ", depth "
						       << c.depth_b << " m, looming " << c.looming;
	}
}

TEST(Groups, ASmallMoverBesideALargeOneIsClusteredAgain)
{
	// A large mover (40 points moving 6 px per frame) and, 30 px to its right, a small one (6 points moving
	// 1.5 px per frame the other way), with a third mover 500 px off that makes the seed's preference (the
	// farthest pair's similarity) low. Among the small one's 24 nearest samples most are the large one's,
	// so Affinity Propagation gives it the large one's exemplar and the member rule takes it out again; the
	// points placed in no group are clustered once more among themselves and make a group of their own.
	std::vector<MotionPoint> points;
	for (int i = 0; i < 40; ++i) {
		MotionPoint p;
		p.px = {100.F + static_cast<float>(i % 8) * 10.F, 200.F + static_cast<float>(i / 8) * 10.F};
		p.flow = p.residual = {6.F, 0.F};
		p.dynamic = true;
		points.push_back(p);
	}
	for (int i = 0; i < 6; ++i) {
		MotionPoint p;
		p.px = {100.F + 70.F + 30.F + static_cast<float>(i % 2) * 10.F,
			210.F + static_cast<float>(i / 2) * 10.F};
		p.flow = p.residual = {-1.5F, 0.F};
		p.dynamic = true;
		points.push_back(p);
	}
	for (int i = 0; i < 20; ++i) {
		MotionPoint p;
		p.px = {700.F + static_cast<float>(i % 5) * 10.F, 400.F + static_cast<float>(i / 5) * 10.F};
		p.flow = p.residual = {-6.F, 0.F};
		p.dynamic = true;
		points.push_back(p);
	}
	for (const bool regroup : {false, true}) {
		GroupParams params;
		params.members = GroupMembers::Labels; // the classifier's dynamic points, slow ones included
		params.regroup_unplaced = regroup;
		const GroupOutput out = second_of_two(points, params);
		ASSERT_EQ(out.groups.size(), regroup ? 3u : 2u) << "regroup " << regroup;
		const auto small = std::find_if(out.groups.begin(), out.groups.end(),
						[](const TargetGroup &g) { return g.point_count == 6; });
		EXPECT_EQ(small != out.groups.end(), regroup) << "regroup " << regroup;
		if (small != out.groups.end()) {
			EXPECT_LT(small->image_velocity_pxps[0], 0.F);
		}
	}
}

TEST(Groups, SeveralMoversLeftoversAreClusteredApart)
{
	// A large mover (40 points moving 6 px per frame to the right) with three small ones around it (6 points
	// each: to its right moving down and right, below it moving up and right, to its left moving slower),
	// and a fourth mover 600 px off that makes the seed's preference (the farthest pair's similarity) low.
	// The first round hands the small ones the large one's exemplar and the member rule takes them out. They
	// are clustered again among themselves; at the first round's preference they still share one exemplar,
	// and the member rule keeps none of them (their median moves like none of them); at a quarter of it each
	// is a group of its own.
	std::vector<MotionPoint> points;
	const auto add = [&points](int count, cv::Point2f at, cv::Point2f motion) {
		const int columns = count >= 20 ? count / 5 : 2;
		for (int i = 0; i < count; ++i) {
			MotionPoint p;
			p.px = at + cv::Point2f(static_cast<float>(i % columns) * 10.F,
						static_cast<float>(i / columns) * 10.F);
			p.flow = p.residual = motion;
			p.dynamic = true;
			points.push_back(p);
		}
	};
	add(40, {100.F, 200.F}, {6.F, 0.F});
	add(6, {200.F, 205.F}, {6.F, 4.F});
	add(6, {110.F, 270.F}, {6.F, -4.F});
	add(6, {40.F, 210.F}, {2.F, 0.F});
	add(20, {700.F, 450.F}, {0.F, 6.F});
	for (const double scale : {1.0, 0.25}) {
		GroupParams params;
		params.members = GroupMembers::Labels;
		params.regroup_preference_scale = scale;
		const GroupOutput out = second_of_two(points, params);
		const auto small = std::count_if(out.groups.begin(), out.groups.end(),
						 [](const TargetGroup &g) { return g.point_count == 6; });
		EXPECT_EQ(small, scale < 1 ? 3 : 0) << "regroup preference scale " << scale;
		EXPECT_EQ(out.groups.size(), 2u + static_cast<size_t>(small)) << "regroup preference scale " << scale;
	}
}

TEST(Groups, MonocularMoversApartWhoMoveAlikeAreCutApart)
{
	// Three walkers on monocular footage, 10 feature points each (2 columns 8 px apart, 5 rows 12 px apart),
	// all moving 3 px per frame to the right, their nearest points 62 px apart, and a fourth walker far off
	// moving left: Affinity Propagation (the seed's preference, from the farthest pair; position scale 40 px)
	// puts the three in one cluster, whose box spans the ground between them. Cut at gaps over split_gap_px
	// (45), each is a group of its own with its box on it: the members' extent grown by box_margin_px. Of two
	// slow points moving a walker's way, the one inside its members' extent joins it (the label rule); the one
	// beside it, in the margin, does not. With depth the cut does not apply: the walkers, at one depth and
	// within merge_reach_m, are one group as before.
	const std::array<float, 3> x0 = {100.F, 170.F, 240.F};
	const geometry::StereoRig rig = test_rig();
	for (const bool with_depth : {false, true})
		for (const double gap : {0.0, 45.0}) {
			std::vector<MotionPoint> points;
			const auto walker = [&](cv::Point2f from, float flow) {
				for (int i = 0; i < 10; ++i) {
					MotionPoint p;
					p.px = {from.x + static_cast<float>(i % 2) * 8.F,
						from.y + static_cast<float>(i / 2) * 12.F};
					p.flow = p.residual = {flow, 0.F};
					p.dynamic = true;
					if (with_depth)
						p.xyz = at_depth(p.px, 6.F, rig);
					points.push_back(p);
				}
			};
			for (const float x : x0)
				walker({x, 200.F}, 3.F);
			walker({600.F, 400.F}, -3.F);
			MotionPoint inside; // within the first walker's points, slower but its way
			inside.px = {104.F, 230.F};
			inside.flow = inside.residual = {1.8F, 0.F};
			MotionPoint beside = inside; // the same motion, in the first walker's margin
			beside.px = {114.F, 230.F};
			points.push_back(inside);
			points.push_back(beside);
			GroupParams params;
			params.members = GroupMembers::Labels;
			params.split_gap_px = gap;
			GroupMotionContext context = tenth_of_a_second();
			if (with_depth)
				context.rig = rig;
			const GroupOutput out = second_of_two(points, params, context);
			const std::string label =
				std::string(with_depth ? "depth" : "no depth") + ", gap " + std::to_string(gap);
			const auto walking_right = [](const TargetGroup &g) { return g.image_velocity_pxps[0] > 0; };
			if (with_depth || gap == 0) {
				ASSERT_EQ(out.groups.size(), 2u) << label;
				const auto three = std::find_if(out.groups.begin(), out.groups.end(), walking_right);
				ASSERT_NE(three, out.groups.end()) << label;
				EXPECT_EQ(three->point_count, 30) << label;
				continue;
			}
			ASSERT_EQ(out.groups.size(), 4u) << label;
			for (const TargetGroup &g : out.groups) {
				if (!walking_right(g))
					continue;
				EXPECT_EQ(g.point_count, 10) << label;
				const float left = g.box_px[0] + static_cast<float>(params.box_margin_px);
				EXPECT_TRUE(std::any_of(x0.begin(), x0.end(),
							[&](float x) { return std::abs(left - x) < 0.01F; }))
					<< "box from " << g.box_px[0] << ": " << label;
				EXPECT_NEAR(g.box_px[2] - g.box_px[0], 8 + 2 * params.box_margin_px, 0.01) << label;
			}
			const size_t n = points.size();
			EXPECT_GE(out.group_of_point[n - 2], 0) << "the slow point inside joins: " << label;
			EXPECT_EQ(out.group_of_point[n - 1], -1) << "the point beside stays out: " << label;
		}
}

namespace {

/// A frame's points for new_corners_of_groups: a static scene of `scene` points on a grid over 640x480, the
/// first `scene_young` of them new to the tracks, and `inside` points on a 10x10 grid in the box
/// (100, 100)-(160, 220), the first `inside_young` of them new.
struct CornerScene {
	std::vector<cv::Point2f> at;
	std::vector<uint32_t> age;
	std::vector<float> depth;
	std::vector<uint8_t> dynamic;
	std::vector<TargetGroup> groups;

	CornerScene(int scene, int scene_young, int inside, int inside_young)
	{
		for (int k = 0; k < scene; ++k)
			add({300.F + static_cast<float>(k % 30) * 10.F, 20.F + static_cast<float>(k / 30) * 10.F},
			    k < scene_young ? 1U : 20U);
		for (int k = 0; k < inside; ++k)
			add({105.F + static_cast<float>(k % 10) * 5.F, 105.F + static_cast<float>(k / 10) * 10.F},
			    k < inside_young ? 1U : 20U);
		TargetGroup g;
		g.box_px = {100, 100, 160, 220};
		groups.push_back(g);
	}
	size_t add(cv::Point2f p, uint32_t a, float z = std::numeric_limits<float>::quiet_NaN())
	{
		at.push_back(p);
		age.push_back(a);
		depth.push_back(z);
		dynamic.push_back(0);
		return at.size() - 1;
	}
	std::vector<uint8_t> found(const GroupParams &params, double margin_px = 0) const
	{
		return new_corners_of_groups(at, age, depth, dynamic, groups, margin_px, params);
	}
};

} // namespace

// GroupParams::new_in_box_frames: a box whose points are new to the tracks far more often than the static
// scene's (a walker's changing corners) hands its new points the group's label, in it and under it by
// new_below_box_share of its height; its old points, new points beside it, and new points further down
// stay as they were. A box no newer than the scene (a rigid mover) hands none.
TEST(GroupLabels, NewCornersOnABoxThatRenewsThemAreTheGroups)
{
	GroupParams params;
	params.new_in_box_frames = 2;
	params.new_below_box_share = 0.5;
	{
		CornerScene s(300, 30, 40, 20); // the scene 10 % new, the box 50 %
		const size_t old_inside = s.add({130, 150}, 5);
		const size_t beside = s.add({170, 150}, 1);
		const size_t under = s.add({130, 270}, 1);     // 50 px under the box: within half its 120 px
		const size_t far_under = s.add({130, 290}, 1); // 70 px under
		const size_t new_outside = s.add({400, 400}, 1);
		const auto found = s.found(params);
		for (size_t k = 300; k < 320; ++k)
			EXPECT_EQ(found[k], 1) << "the box's new point " << k;
		for (size_t k = 320; k < 340; ++k)
			EXPECT_EQ(found[k], 0) << "the box's old point " << k;
		EXPECT_EQ(found[old_inside], 0);
		EXPECT_EQ(found[beside], 0);
		EXPECT_EQ(found[under], 1);
		EXPECT_EQ(found[far_under], 0);
		EXPECT_EQ(found[new_outside], 0);
		params.new_below_box_share = 0;
		EXPECT_EQ(s.found(params)[under], 0) << "the box only";
		// A margin of 8 px around the members: a new point 5 px inside the box's edge is in it, not theirs.
		const size_t in_margin = s.add({155, 150}, 1);
		EXPECT_EQ(s.found(params)[in_margin], 1);
		EXPECT_EQ(s.found(params, 8)[in_margin], 0);
		EXPECT_EQ(s.found(params, 8)[315], 1) << "a new point well inside (130, 115)";
		params.new_below_box_share = 0.5;
		params.new_in_box_frames = 0;
		const auto off = s.found(params);
		EXPECT_EQ(std::count(off.begin(), off.end(), 1), 0) << "off";
		params.new_in_box_frames = 2;
		s.dynamic[300] = 1;
		EXPECT_EQ(s.found(params)[300], 0) << "a point already dynamic is left as it is";
	}
	{
		CornerScene s(300, 30, 40, 6); // the box 15 %: under twice the scene's 10 %
		const auto found = s.found(params);
		EXPECT_EQ(std::count(found.begin(), found.end(), 1), 0);
		EXPECT_EQ(boxes_renewing_corners(s.at, s.age, s.dynamic, s.groups, 2, 5)[0], 0);
	}
	{
		CornerScene s(300, 30, 40, 9); // 22.5 %: over twice 10 %
		EXPECT_EQ(boxes_renewing_corners(s.at, s.age, s.dynamic, s.groups, 2, 5)[0], 1);
		EXPECT_EQ(boxes_renewing_corners(s.at, s.age, s.dynamic, s.groups, 2, 50)[0], 0)
			<< "fewer points in the box than min_points";
	}
}

// With depth, a new point in a renewing box is the group's only at the group's depth (split_same_depth).
TEST(GroupLabels, NewCornersJoinOnlyAtTheGroupsDepth)
{
	GroupParams params;
	params.new_in_box_frames = 2;
	params.split_same_depth = 0.1;
	CornerScene s(300, 30, 40, 20);
	s.groups[0].position_m = std::array<double, 3>{0.5, 0.2, 5.0};
	const size_t near_it = s.add({130, 150}, 1, 5.3F);
	const size_t behind = s.add({131, 150}, 1, 8.0F);
	const size_t in_front = s.add({132, 150}, 1, 3.0F);
	const size_t no_depth = s.add({133, 150}, 1);
	const auto found = s.found(params);
	EXPECT_EQ(found[near_it], 1);
	EXPECT_EQ(found[behind], 0);
	EXPECT_EQ(found[in_front], 0);
	EXPECT_EQ(found[no_depth], 1);
}
