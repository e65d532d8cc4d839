// Known answers for the stereo geometry: triangulation, sparse stereo on constructed images, PnP on
// constructed points, seed 001's eq. 1 and eq. 4 on hand-computed cases, the motion prior.
#include <cmath>
#include <numbers>
#include <random>
#include <utility>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/geometry/rig.hpp"
#include "core/vision/ego.hpp"
#include "core/vision/features.hpp"
#include "core/vision/matching.hpp"
#include "core/vision/stereo.hpp"
#include "core/vision/temporal.hpp"

using namespace stereod;
using namespace stereod::vision;

namespace {

const geometry::StereoRig kRig{800, 800, 320, 240, 0.1};

/// Random texture, smoothed so features and SAD windows have structure at a few pixels.
cv::Mat texture(int width, int height, uint64_t seed)
{
	cv::Mat noise(height, width, CV_8UC1);
	cv::theRNG().state = seed;
	cv::randu(noise, 0, 255);
	cv::Mat smooth;
	cv::GaussianBlur(noise, smooth, cv::Size(0, 0), 1.5);
	cv::normalize(smooth, smooth, 0, 255, cv::NORM_MINMAX);
	return smooth;
}

/// The right view of a fronto-parallel plane at disparity d: the left image shifted left by d pixels
/// (sub-pixel by bilinear warp).
cv::Mat shifted(const cv::Mat &left, double d)
{
	cv::Mat right;
	const cv::Matx23d shift(1, 0, -d, 0, 1, 0);
	cv::warpAffine(left, right, shift, left.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT_101);
	return right;
}

} // namespace

TEST(Geometry, TriangulatesAndProjectsBack)
{
	// z = f b / d = 800 * 0.1 / 16 = 5 m; x = (u - cx) z / f = (400 - 320) * 5 / 800 = 0.5 m.
	const auto p = kRig.triangulate(400, 200, 16);
	ASSERT_TRUE(p.has_value());
	EXPECT_NEAR((*p)[0], 0.5, 1e-12);
	EXPECT_NEAR((*p)[1], -0.25, 1e-12);
	EXPECT_NEAR((*p)[2], 5.0, 1e-12);
	const auto back = kRig.project(*p);
	ASSERT_TRUE(back.has_value());
	EXPECT_NEAR(back->x, 400, 1e-9);
	EXPECT_NEAR(back->y, 200, 1e-9);
	EXPECT_FALSE(kRig.triangulate(400, 200, 0).has_value());
	EXPECT_FALSE(kRig.triangulate(400, 200, -3).has_value());
	EXPECT_FALSE(kRig.project(cv::Vec3d(1, 1, -2)).has_value());
	// dz = z^2 / (f b) * sigma_d = 25 / 80 * 0.5
	EXPECT_NEAR(kRig.depth_sigma(5, 0.5), 0.15625, 1e-12);
}

TEST(Geometry, PosesComposeInvertAndRoundTripQuaternions)
{
	geometry::Pose a{geometry::rotation_from_vector({0.1, -0.2, 0.3}), {1, 2, 3}};
	const geometry::Pose identity = a * a.inverse();
	EXPECT_NEAR(identity.angle(), 0, 1e-12);
	EXPECT_NEAR(a.angle(), std::sqrt(0.01 + 0.04 + 0.09), 1e-12);
	EXPECT_NEAR(identity.distance(), 0, 1e-12);
	const auto q = geometry::quaternion_from_rotation(a.r);
	const cv::Matx33d back = geometry::rotation_from_quaternion(q[0], q[1], q[2], q[3]);
	EXPECT_LT(cv::norm(back - a.r), 1e-12);
	EXPECT_EQ(geometry::Pose::from_matrix(a.matrix()).t, a.t);
	// A half turn about x: quaternion (1, 0, 0, 0).
	const auto half = geometry::quaternion_from_rotation(geometry::rotation_from_vector({CV_PI, 0, 0}));
	EXPECT_NEAR(std::abs(half[0]), 1, 1e-12);
	EXPECT_THROW(geometry::rotation_from_quaternion(0, 0, 0, 0), std::invalid_argument);
}

TEST(Geometry, EpipolarDistanceByHand)
{
	// Camera moves 1 m along x, no rotation, K = identity-like with f = 1, c = 0: F = [t]x, the epipolar line
	// of x_a = (0, 0) is y = 0 (the image rows); a point at (5, 3) is 3 away from it.
	const cv::Matx33d k = cv::Matx33d::eye();
	geometry::Pose b_from_a;
	b_from_a.t = {1, 0, 0};
	const cv::Matx33d f = geometry::fundamental_from_pose(k, b_from_a);
	EXPECT_NEAR(geometry::epipolar_distance(f, {0, 0}, {5, 3}), 3.0, 1e-12);
	EXPECT_NEAR(geometry::epipolar_distance(f, {2, 1}, {7, 1}), 0.0, 1e-12);
	// No translation: no epipolar geometry.
	EXPECT_TRUE(std::isinf(
		geometry::epipolar_distance(geometry::fundamental_from_pose(k, geometry::Pose{}), {1, 1}, {2, 2})));
}

TEST(Geometry, SeedEquationsOneAndFourByHand)
{
	// The camera walks 0.1 m forward (x_curr = x_prev - t for a static point: t = (0, 0, -0.1)).
	EgoParams params;
	params.pixel_sigma_px = 1.0;
	params.chi2_quantile = 0.99;
	geometry::Pose curr_from_prev;
	curr_from_prev.t = {0, 0, -0.1};
	const GeometricContext context = GeometricContext::make(kRig, curr_from_prev, 0.3, params);
	// A static point 4 m ahead, 1 m right: at frame n-1 it is at u = 320 + 800 * 1 / 4 = 520; at frame n
	// at 3.9 m: u = 320 + 800 / 3.9 = 525.128..., depth 3.9 m.
	const cv::Vec3f prev_xyz(1, 0, 4);
	const cv::Point2f prev_px(520, 240);
	const cv::Point2f cur_px(static_cast<float>(320 + 800 / 3.9), 240);
	const GeometricTest still = geometric_test(context, prev_px, prev_xyz, cur_px, 3.9F);
	EXPECT_EQ(still.dof, 3);
	EXPECT_NEAR(still.d1_px, 0, 1e-3);
	EXPECT_NEAR(still.d2_m, 0, 1e-6); // eq. 4: Z_pred - Z_meas = 3.9 - 3.9
	EXPECT_FALSE(still.moving);

	// The same pixels, but the depth now measured 3.5 m: the point came 0.4 m nearer than the camera's walk
	// explains (a person walking at the camera). Eq. 4: d2 = 3.9 - 3.5 = 0.4 m; the depth noise at 3.9 and
	// 3.5 m with 0.3 px disparity noise is 3.9^2/80*0.3 = 0.0570 and 3.5^2/80*0.3 = 0.0459, so
	// (0.4)^2 / (0.0570^2 + 0.0459^2) = 29.9, far above chi2(3 dof, 99%) = 11.3.
	const GeometricTest toward = geometric_test(context, prev_px, prev_xyz, cur_px, 3.5F);
	EXPECT_NEAR(toward.d2_m, 0.4, 1e-6);
	EXPECT_NEAR(toward.statistic, 0.16 / (0.057037 * 0.057037 + 0.0459375 * 0.0459375), 0.05);
	EXPECT_TRUE(toward.moving);

	// Moved 5 px down (across the epipolar line, which is the row here): eq. 1 gives d1 = 5 px;
	// 5^2 / (2 * 1^2) = 12.5 alone passes the 1-dof gate 6.63.
	const GeometricTest sideways = geometric_test(context, prev_px, prev_xyz, cur_px + cv::Point2f(0, 5), 3.9F);
	EXPECT_NEAR(sideways.d1_px, 5, 1e-3);
	EXPECT_TRUE(sideways.moving);

	// Without depth at frame n-1, only eq. 1 can be evaluated.
	const cv::Vec3f unknown(NAN, NAN, NAN);
	const GeometricTest d1_only = geometric_test(context, prev_px, unknown, cur_px + cv::Point2f(0, 5), NAN);
	EXPECT_EQ(d1_only.dof, 1);
	EXPECT_TRUE(d1_only.moving);
	EXPECT_FALSE(geometric_test(context, prev_px, unknown, cur_px, NAN).moving);
}

TEST(Geometry, NormalQuantilesAreExact)
{
	// Published values of the inverse standard normal CDF, in the centre and in both tails.
	EXPECT_DOUBLE_EQ(normal_quantile(0.5), 0.0);
	EXPECT_NEAR(normal_quantile(0.975), 1.959963984540054, 1e-12);
	EXPECT_NEAR(normal_quantile(0.99), 2.326347874040841, 1e-12);
	EXPECT_NEAR(normal_quantile(0.999), 3.090232306167814, 1e-12);
	EXPECT_NEAR(normal_quantile(0.01), -2.326347874040841, 1e-12);
	EXPECT_NEAR(normal_quantile(1e-6), -4.753424308822899, 1e-10);
	EXPECT_NEAR(normal_quantile(0.3), -0.524400512708041, 1e-12);
	// The CDF of the quantile gives back p, across the range.
	for (double p = 0.001; p < 1; p += 0.0137)
		EXPECT_NEAR(0.5 * std::erfc(-normal_quantile(p) / std::numbers::sqrt2), p, 1e-14) << p;
}

TEST(Geometry, ChiSquareQuantilesAreClose)
{
	EXPECT_NEAR(chi2_quantile(1, 0.99), 6.635, 0.15);
	EXPECT_NEAR(chi2_quantile(2, 0.99), 9.210, 0.1);
	EXPECT_NEAR(chi2_quantile(3, 0.99), 11.345, 0.1);
	EXPECT_NEAR(chi2_quantile(3, 0.95), 7.815, 0.1);
}

TEST(Geometry, PnpRecoversAKnownPoseDespiteOutliers)
{
	geometry::Pose truth{geometry::rotation_from_vector({0.01, -0.02, 0.005}), {0.03, -0.01, 0.05}};
	std::mt19937 rng(7);
	std::uniform_real_distribution<double> unit(0, 1);
	std::vector<cv::Vec3f> xyz;
	std::vector<cv::Point2f> px;
	for (int i = 0; i < 300; ++i) {
		const double z = 2 + 20 * unit(rng);
		const auto p = *kRig.triangulate(unit(rng) * 639, unit(rng) * 479, kRig.fx * kRig.baseline_m / z);
		auto q = *kRig.project(truth * p);
		if (i % 4 == 0) // a quarter move on their own: a mover
			q += cv::Point2d(15 + 10 * unit(rng), -8);
		xyz.emplace_back(p);
		px.emplace_back(q);
	}
	std::vector<uint8_t> votes(xyz.size(), 1);
	const PoseEstimate e = estimate_pose(xyz, px, votes, kRig, EgoParams{});
	ASSERT_TRUE(e.valid) << e.reason;
	EXPECT_NEAR(e.inliers, 225, 3);
	EXPECT_LT(cv::norm(e.curr_from_prev.t - truth.t), 1e-4);
	EXPECT_LT((e.curr_from_prev.inverse() * truth).angle(), 1e-5);
	for (size_t i = 0; i < xyz.size(); i += 4)
		EXPECT_EQ(e.inlier_mask[i], 0) << "the mover's point " << i << " voted";
	// Adaptive RANSAC: with 3/4 inliers a sample is all inliers with probability 0.42, so 0.999 confidence
	// needs log(0.001) / log(0.58) = 12.7 -> 13 samples once the best hypothesis is found (it may take a few
	// more to find it), in each of the two fits (noise-free points: the second at min_ransac_threshold_px);
	// drawing all 200 in both gives the same pose.
	EXPECT_EQ(e.threshold_px, EgoParams{}.min_ransac_threshold_px);
	EXPECT_GE(e.samples, 2 * 12);
	EXPECT_LE(e.samples, 2 * 40);
	EgoParams exhaustive;
	exhaustive.ransac_confidence = 0;
	const PoseEstimate all = estimate_pose(xyz, px, votes, kRig, exhaustive);
	EXPECT_EQ(all.samples, 2 * 200);
	EXPECT_EQ(all.inliers, e.inliers);
	EXPECT_LT(cv::norm(all.curr_from_prev.t - e.curr_from_prev.t), 1e-6);

	// Too few points with depth: not valid, and why.
	const PoseEstimate few = estimate_pose(std::span(xyz).first(5), std::span(px).first(5), votes, kRig, {});
	EXPECT_FALSE(few.valid);
	EXPECT_NE(few.reason.find("only 5"), std::string::npos);
}

TEST(Geometry, LocalRefinementPullsADriftedChainBackToTheAnchors)
{
	// 120 anchored points 3-12 m ahead; the camera truly 1.5 m along z and turned 3 degrees about y. The
	// chain has drifted 2 cm sideways and 0.3 degrees.
	cv::RNG rng(7);
	geometry::Pose world_from_true;
	world_from_true.r = geometry::rotation_from_vector(cv::Vec3d(0, 3.0 * CV_PI / 180, 0));
	world_from_true.t = cv::Vec3d(0.1, 0, 1.5);
	const geometry::Pose true_from_world = world_from_true.inverse();
	std::vector<AnchorView> anchors;
	while (anchors.size() < 120) {
		const cv::Vec3d world(rng.uniform(-4.0, 4.0), rng.uniform(-2.0, 2.0), rng.uniform(4.5, 13.5));
		const auto p = kRig.project(true_from_world * world);
		if (!p || p->x < 0 || p->y < 0 || p->x >= 640 || p->y >= 480)
			continue;
		anchors.push_back({cv::Vec3f(world), cv::Point2f(static_cast<float>(p->x + rng.gaussian(0.2)),
								 static_cast<float>(p->y + rng.gaussian(0.2)))});
	}
	geometry::Pose drift;
	drift.r = geometry::rotation_from_vector(cv::Vec3d(0, 0.3 * CV_PI / 180, 0));
	drift.t = cv::Vec3d(0.02, 0, 0);
	const geometry::Pose chained = world_from_true * drift;
	EgoParams params;
	params.ransac_threshold_px = 8; // the drift moves the points by up to ~6 px
	params.anchor_refine_gain = 1;	// the whole correction at once
	const AnchorRefinement refined = refine_against_anchors(anchors, chained, kRig, params);
	ASSERT_TRUE(refined.applied);
	EXPECT_EQ(refined.points, 120);
	EXPECT_GE(refined.inliers, 115);
	EXPECT_LT(refined.rms_after_px, refined.rms_before_px);
	const geometry::Pose error = refined.world_from_camera.inverse() * world_from_true;
	EXPECT_LT(cv::norm(error.t), 0.003);
	EXPECT_LT(cv::norm(geometry::vector_from_rotation(error.r)), 0.05 * CV_PI / 180);

	// Half the correction with anchor_refine_gain 0.5.
	params.anchor_refine_gain = 0.5;
	const AnchorRefinement half = refine_against_anchors(anchors, chained, kRig, params);
	ASSERT_TRUE(half.applied);
	const geometry::Pose half_error = half.world_from_camera.inverse() * world_from_true;
	EXPECT_NEAR(cv::norm(half_error.t), cv::norm((chained.inverse() * world_from_true).t) / 2, 0.003);
	params.anchor_refine_gain = 1;

	// Too few anchors: the chain stays as it is.
	params.anchor_refine_min_points = 121;
	const AnchorRefinement refused = refine_against_anchors(anchors, chained, kRig, params);
	EXPECT_FALSE(refused.applied);
	EXPECT_LT(cv::norm((refused.world_from_camera.inverse() * chained).t), 1e-12);

	// A correction beyond 5 cm is not the chain's slow drift: refused.
	drift.r = cv::Matx33d::eye();
	drift.t = cv::Vec3d(0, 0, 0.3); // 30 cm along the view axis moves far points by little
	params.anchor_refine_min_points = 30;
	const AnchorRefinement leap = refine_against_anchors(anchors, world_from_true * drift, kRig, params);
	EXPECT_FALSE(leap.applied);
	EXPECT_GE(leap.inliers, 30); // refused by the bound, not for want of points
}

TEST(Geometry, TheSecondFitAtTheMeasuredNoiseLetsTheNearStaticPointsDecideTheTranslation)
{
	// The trade far points cannot see: a camera stepping 30 mm sideways while turning so that a wall 15 m
	// away looks the same. A mover at 7 m walking along the optical axis fits that wrong motion exactly and
	// the true one within 1.1 px; the near static ground (3.5-5 m, spread along the bottom of the image) fits
	// the true motion and misses the wrong one by 2.3-3.8 px. Every point carries 0.05 px of noise, the
	// clean sim's. At a fixed 2 px both motions keep the mover, which pulls the least-squares pose along the
	// trade; at three times the measured noise the mover drops out of the true motion.
	const geometry::Pose truth{geometry::rotation_from_vector({0.0, 0.002, 0.0}), {0.0005, 0.0, 0.0}};
	const double wall_z = 15, step = 0.03;
	const geometry::Pose wrong{geometry::rotation_from_vector({0.0, 0.002 - step / wall_z, 0.0}),
				   truth.t + cv::Vec3d(step, 0, 0)};
	std::mt19937 rng(5);
	std::uniform_real_distribution<double> unit(0, 1);
	std::normal_distribution<double> noise(0, 0.05);
	std::vector<cv::Vec3f> xyz;
	std::vector<cv::Point2f> px;
	const auto add = [&](double u, double v, double z, const geometry::Pose &motion) {
		const auto p = *kRig.triangulate(u, v, kRig.fx * kRig.baseline_m / z);
		xyz.emplace_back(p);
		px.emplace_back(*kRig.project(motion * p) + cv::Point2d(noise(rng), noise(rng)));
	};
	for (int i = 0; i < 200; ++i) // the wall over the upper two thirds
		add(20 + 600 * unit(rng), 10 + 300 * unit(rng), wall_z, truth);
	for (int i = 0; i < 20; ++i) // the ground below: sparse, spread
		add(20 + 600 * unit(rng), 380 + 80 * unit(rng), 3.5 + 1.5 * unit(rng), truth);
	for (int i = 0; i < 60; ++i) // the mover: compact, dense, not yet known to move
		add(100 + 50 * unit(rng), 250 + 120 * unit(rng), 7 + 0.2 * unit(rng), wrong);
	const std::vector<uint8_t> votes(xyz.size(), 1);
	EgoParams one_fit;
	one_fit.ransac_threshold_sigmas = 0;
	const PoseEstimate loose = estimate_pose(xyz, px, votes, kRig, one_fit);
	ASSERT_TRUE(loose.valid) << loose.reason;
	EXPECT_EQ(loose.threshold_px, 2.0);
	// Measured: one fit 20.8 mm off, two 0.19 mm.
	EXPECT_GT(cv::norm(loose.curr_from_prev.t - truth.t), 0.005) << "the mover no longer pulls: the test is moot";
	const PoseEstimate tight = estimate_pose(xyz, px, votes, kRig, EgoParams{});
	ASSERT_TRUE(tight.valid) << tight.reason;
	// The first fit's compromise leaves its residuals at 0.26 px (median over all points), so the second fit's
	// distance is 0.79 px: still under the 1.1 px the mover misses the true motion by.
	EXPECT_GT(tight.threshold_px, 0.5);
	EXPECT_LT(tight.threshold_px, 1.0);
	EXPECT_NEAR(tight.residual_sigma_px, 0.05, 0.02);
	EXPECT_LT(cv::norm(tight.curr_from_prev.t - truth.t), 0.002);
	int mover_inliers = 0, ground_inliers = 0;
	for (size_t i = 200; i < 220; ++i)
		ground_inliers += tight.inlier_mask[i];
	for (size_t i = 220; i < xyz.size(); ++i)
		mover_inliers += tight.inlier_mask[i];
	EXPECT_GE(ground_inliers, 18);
	EXPECT_LE(mover_inliers, 3);

	// With the previous frame's noise carried by the prior (bounds wide open here, so they decide nothing),
	// one fit at three times that noise (0.5 px, the floor) gives the same answer.
	MotionPrior carried;
	carried.predicted = truth;
	carried.translation_tolerance_m = 1;
	carried.rotation_tolerance_rad = 1;
	carried.noise_px = 0.05;
	const PoseEstimate once = estimate_pose(xyz, px, votes, kRig, EgoParams{}, &carried);
	ASSERT_TRUE(once.valid) << once.reason;
	EXPECT_EQ(once.threshold_px, 0.5);
	EXPECT_LT(once.samples, tight.samples);
	EXPECT_LT(cv::norm(once.curr_from_prev.t - truth.t), 0.002);
}

TEST(Geometry, RansacTakesTheSpreadOutSceneOverALargerCompactMover)
{
	// 100 static points spread over the image at 2-22 m, and 150 points on a mover: a compact patch 60 px
	// across at 6 m that moves rigidly (0.3 m to the right, 40 px). Counted by inliers the mover's motion wins
	// (150 and more against 100); counted by the grid cells its inliers cover, the camera's own. All 200
	// samples are drawn (confidence 0) so that both rules see the same hypotheses: adaptive RANSAC stops
	// sooner when the mover's hypothesis comes first.
	const geometry::Pose truth{geometry::rotation_from_vector({0.0, 0.003, 0.0}), {0.001, 0.0, 0.0}};
	const geometry::Pose mover_motion{truth.r, truth.t + cv::Vec3d(0.3, 0, 0)};
	std::mt19937 rng(11);
	std::uniform_real_distribution<double> unit(0, 1);
	std::vector<cv::Vec3f> xyz;
	std::vector<cv::Point2f> px;
	for (int i = 0; i < 100; ++i) {
		const double z = 2 + 20 * unit(rng);
		const auto p = *kRig.triangulate(unit(rng) * 639, unit(rng) * 479, kRig.fx * kRig.baseline_m / z);
		xyz.emplace_back(p);
		px.emplace_back(*kRig.project(truth * p));
	}
	for (int i = 0; i < 150; ++i) {
		const auto p = *kRig.triangulate(300 + 60 * unit(rng), 200 + 60 * unit(rng),
						 kRig.fx * kRig.baseline_m / (6 + 0.2 * unit(rng)));
		xyz.emplace_back(p);
		px.emplace_back(*kRig.project(mover_motion * p));
	}
	const std::vector<uint8_t> votes(xyz.size(), 1);
	EgoParams by_spread;
	by_spread.ransac_confidence = 0;
	const PoseEstimate spread = estimate_pose(xyz, px, votes, kRig, by_spread);
	ASSERT_TRUE(spread.valid) << spread.reason;
	EXPECT_EQ(spread.inliers, 100);
	EXPECT_LT(cv::norm(spread.curr_from_prev.t - truth.t), 1e-4);
	EgoParams by_count = by_spread;
	by_count.ransac_spread_score = false;
	const PoseEstimate counted = estimate_pose(xyz, px, votes, kRig, by_count);
	ASSERT_TRUE(counted.valid) << counted.reason;
	EXPECT_GE(counted.inliers, 150);
	EXPECT_GT(cv::norm(counted.curr_from_prev.t - truth.t), 0.1);
}

TEST(Geometry, TheTestsNoiseIsMeasuredFromThePoseFit)
{
	// Static points seen with 0.3 px of Gaussian noise per axis, a tenth of them movers: the pose fit's
	// residuals give the noise back (the median of the residual norms over 1.1774), and the test uses it.
	const geometry::Pose truth{geometry::rotation_from_vector({0.002, 0.01, 0}), {0.02, 0, 0.05}};
	std::mt19937 rng(11);
	std::uniform_real_distribution<double> unit(0, 1);
	std::normal_distribution<double> noise(0, 0.3);
	std::vector<cv::Vec3f> xyz;
	std::vector<cv::Point2f> px;
	for (int i = 0; i < 2000; ++i) {
		const double z = 2 + 20 * unit(rng);
		const auto p = *kRig.triangulate(unit(rng) * 639, unit(rng) * 479, kRig.fx * kRig.baseline_m / z);
		auto q = *kRig.project(truth * p) + cv::Point2d(noise(rng), noise(rng));
		if (i % 10 == 0)
			q += cv::Point2d(12, 4);
		xyz.emplace_back(p);
		px.emplace_back(q);
	}
	const std::vector<uint8_t> votes(xyz.size(), 1);
	EgoParams params;
	const PoseEstimate e = estimate_pose(xyz, px, votes, kRig, params);
	ASSERT_TRUE(e.valid) << e.reason;
	// The tenth that moved pulls the median up a little (the 50th percentile of the static points becomes
	// their 55th): 0.3 * sqrt(-2 ln 0.444) / 1.1774 = 0.325.
	EXPECT_NEAR(e.residual_sigma_px, 0.325, 0.025);
	const GeometricContext measured = GeometricContext::make(kRig, truth, 0.3, params, e.residual_sigma_px);
	EXPECT_NEAR(measured.residual_var_px2, e.residual_sigma_px * e.residual_sigma_px, 1e-12);
	params.measured_noise = false;
	EXPECT_NEAR(GeometricContext::make(kRig, truth, 0.3, params, e.residual_sigma_px).residual_var_px2, 2.0, 1e-12);
	// Never below the floor, whatever a noiseless fit says.
	params.measured_noise = true;
	EXPECT_NEAR(GeometricContext::make(kRig, truth, 0.3, params, 0.01).residual_var_px2, 0.01, 1e-12);
}

TEST(Geometry, DisparityNoiseIsMeasuredFromTheInliers)
{
	// Points 3-20 m away, the camera 5 cm forward; frame n's disparity measured with 0.2 px of noise. Each
	// difference carries the noise of one prediction-free measurement and the frame n-1 depth's (here
	// exact), so the estimate over sqrt 2 is 0.2 / sqrt 2; points outside the inlier mask do not count.
	geometry::Pose curr_from_prev;
	curr_from_prev.t = {0, 0, -0.05};
	std::mt19937 rng(5);
	std::uniform_real_distribution<double> unit(0, 1);
	std::normal_distribution<double> noise(0, 0.2);
	std::vector<cv::Vec3f> xyz;
	std::vector<float> depth;
	std::vector<uint8_t> inlier;
	const double fb = kRig.fx * kRig.baseline_m;
	for (int i = 0; i < 4000; ++i) {
		const auto p = *kRig.triangulate(unit(rng) * 639, unit(rng) * 479, fb / (3 + 17 * unit(rng)));
		const double z_now = (curr_from_prev * p)[2];
		const bool outlier = i % 5 == 0;
		depth.push_back(static_cast<float>(fb / (fb / z_now + noise(rng) + (outlier ? 3.0 : 0.0))));
		xyz.emplace_back(p);
		inlier.push_back(outlier ? 0 : 1);
	}
	const double sigma = measured_disparity_sigma(xyz, depth, inlier, curr_from_prev, kRig, 15);
	EXPECT_NEAR(sigma, 0.2 / std::sqrt(2.0), 0.01);
	// Too few inliers with depth: nothing measured.
	EXPECT_EQ(measured_disparity_sigma(std::span(xyz).first(10), std::span(depth).first(10), inlier, curr_from_prev,
					   kRig, 15),
		  0);
}

TEST(Geometry, ConfirmationNeedsTheSameOwnMotionTwice)
{
	// var = 0.1^2 per axis, change 0.25: for r = (5, 0) the innovation's variance is 2 * 0.01 + 0.0625 * 25
	// = 1.5825, and the 2-dof 99 % gate 9.21 allows |r - r_prev|^2 up to 14.57: 3.82 px.
	EXPECT_TRUE(continues_motion({5, 0}, {1.5, 0}, 0.01, 0.25, 0.99));  // 3.5 px apart
	EXPECT_FALSE(continues_motion({5, 0}, {1.0, 0}, 0.01, 0.25, 0.99)); // 4 px apart
	EXPECT_FALSE(continues_motion({5, 0}, {-20, 3}, 0.01, 0.25, 0.99)); // a mismatch jumps
	// Nothing to compare with, or the check off: confirmed.
	EXPECT_TRUE(continues_motion({5, 0}, {NAN, NAN}, 0.01, 0.25, 0.99));
	EXPECT_TRUE(continues_motion({5, 0}, {-20, 3}, 0.01, 0, 0.99));
}

TEST(Geometry, AStillCameraStillTestsTheDepth)
{
	// No translation (no epipolar line): the residual is tested whole (2 dof) and the depth too, so a
	// person walking straight at a still camera, whose image hardly moves, is seen by eq. 4. Point 4 m
	// ahead on the axis; it comes 0.3 m nearer. Depth noise at 4 m and 3.7 m with 0.3 px:
	// 16/80*0.3 = 0.06 and 13.69/80*0.3 = 0.0513; (0.3)^2 / (0.06^2 + 0.0513^2) = 14.6 > chi2(3, 99%) 11.3.
	EgoParams params;
	params.pixel_sigma_px = 1.0;
	const GeometricContext context = GeometricContext::make(kRig, geometry::Pose{}, 0.3, params);
	const cv::Vec3f on_axis(0, 0, 4);
	const GeometricTest still = geometric_test(context, {320, 240}, on_axis, {320, 240}, 4.0F);
	EXPECT_EQ(still.dof, 3);
	EXPECT_FALSE(still.moving);
	const GeometricTest nearer = geometric_test(context, {320, 240}, on_axis, {320, 240}, 3.7F);
	EXPECT_EQ(nearer.dof, 3);
	EXPECT_NEAR(nearer.d2_m, 0.3, 1e-6);
	EXPECT_NEAR(nearer.statistic, 0.09 / (0.06 * 0.06 + 0.0513375 * 0.0513375), 0.05);
	EXPECT_TRUE(nearer.moving);
}

TEST(Geometry, MotionPriorRefusesWhatNoAccelerationExplains)
{
	// Far points cannot tell a turn from a sideways step; a near mover holds most of the points. Without
	// a prior RANSAC takes "the camera followed the mover"; the prior (the camera was still) refuses it.
	geometry::Pose truth; // the camera stands still
	std::vector<cv::Vec3f> xyz;
	std::vector<cv::Point2f> px;
	std::mt19937 rng(3);
	std::uniform_real_distribution<double> unit(0, 1);
	for (int i = 0; i < 240; ++i) {
		const bool mover = i < 150;
		const double z = mover ? 2.5 + 0.3 * unit(rng) : (i < 220 ? 40 + 20 * unit(rng) : 4 + 4 * unit(rng));
		const double u = mover ? 100 + 120 * unit(rng) : unit(rng) * 639;
		const auto p = *kRig.triangulate(u, unit(rng) * 479, kRig.fx * kRig.baseline_m / z);
		cv::Vec3d moved = p;
		if (mover)
			moved += cv::Vec3d(0.05, 0, 0); // 5 cm sideways in one frame: 1.5 m/s
		xyz.emplace_back(p);
		px.emplace_back(*kRig.project(truth * moved));
	}
	std::vector<uint8_t> votes(xyz.size(), 1);
	EgoParams params;
	const PoseEstimate blind = estimate_pose(xyz, px, votes, kRig, params);
	ASSERT_TRUE(blind.valid);
	EXPECT_GT(cv::norm(blind.curr_from_prev.t), 0.02) << "the scene was meant to fool a prior-free RANSAC";
	const MotionPrior prior = MotionPrior::constant_velocity(geometry::Pose{}, 1 / 30.0, 1 / 30.0, params);
	EXPECT_NEAR(prior.translation_tolerance_m, 10.0 / 900, 1e-9);
	const PoseEstimate told = estimate_pose(xyz, px, votes, kRig, params, &prior);
	ASSERT_TRUE(told.valid) << told.reason;
	EXPECT_LT(cv::norm(told.curr_from_prev.t), 0.003);
	EXPECT_EQ(told.inlier_mask[0], 0);
}

TEST(Stereo, RefinesDisparityToAFractionOfAPixel)
{
	const cv::Mat left = texture(200, 100, 11);
	for (double d : {7.0, 7.25, 7.5, 12.8}) {
		const cv::Mat right = shifted(left, d);
		const float refined = refine_disparity(left, right, {100, 50}, static_cast<float>(std::round(d)), 2, 5);
		EXPECT_NEAR(refined, d, 0.12) << "true disparity " << d;
	}
	// Off by more than the search radius: the minimum sits on the edge and the match is refused.
	const cv::Mat right = shifted(left, 20);
	EXPECT_TRUE(std::isnan(refine_disparity(left, right, {100, 50}, 10, 2, 5)));
	// Near the border: no window.
	EXPECT_TRUE(std::isnan(refine_disparity(left, right, {2, 50}, 10, 2, 5)));
}

namespace {

/// A 200x100 stereo pair: a near textured surface (disparity `near`) left of column `edge` beside a farther one
/// (`far`), at the near one's right edge, where the right eye sees the far one uncovered.
std::pair<cv::Mat, cv::Mat> depth_edge_pair(int edge, int far, int near)
{
	const cv::Mat far_surface = texture(200, 100, 21), near_surface = texture(200, 100, 22);
	cv::Mat left(100, 200, CV_8UC1), right(100, 200, CV_8UC1);
	for (int y = 0; y < 100; ++y)
		for (int x = 0; x < 200; ++x) {
			left.at<uint8_t>(y, x) =
				x < edge ? near_surface.at<uint8_t>(y, x) : far_surface.at<uint8_t>(y, x);
			right.at<uint8_t>(y, x) = x + near < edge ? near_surface.at<uint8_t>(y, x + near)
								  : far_surface.at<uint8_t>(y, std::min(199, x + far));
		}
	return {left, right};
}

} // namespace

// A window across a depth edge holds two disparities: a near textured surface (disparity 14, left of column 100)
// beside a farther one (11), at the near one's right edge, where the right eye sees the far one uncovered. With
// stereo.edge_split_px the point whose window straddles the edge is marked; points wholly on either surface are
// not.
TEST(Stereo, AWindowAcrossADepthEdgeIsMarked)
{
	constexpr int kEdge = 100, kFar = 11, kNear = 14;
	const std::pair<cv::Mat, cv::Mat> pair = depth_edge_pair(kEdge, kFar, kNear);
	const cv::Mat &left = pair.first, &right = pair.second;
	const auto straddles = [&](float u, int d, double split) {
		bool across = false;
		const float refined =
			refine_disparity(left, right, {u, 50}, static_cast<float>(d), 2, 5, split, &across);
		EXPECT_TRUE(std::isfinite(refined)) << "at " << u;
		return across;
	};
	EXPECT_NEAR(refine_disparity(left, right, {60, 50}, kNear, 2, 5), kNear, 0.12) << "wholly on the near surface";
	EXPECT_NEAR(refine_disparity(left, right, {140, 50}, kFar, 2, 5), kFar, 0.12) << "wholly on the far surface";
	EXPECT_FALSE(straddles(60, kNear, 1.0));
	EXPECT_FALSE(straddles(140, kFar, 1.0));
	// Half the window on each surface: its left half prefers 14, its right half 11, the whole window
	// something between that is neither surface's.
	EXPECT_TRUE(straddles(kEdge, (kNear + kFar) / 2, 1.0));
	// Halves that agree within the threshold pass: a wide one lets this window through, and 0 is no test.
	EXPECT_FALSE(straddles(kEdge, (kNear + kFar) / 2, 5.0));
	EXPECT_FALSE(straddles(kEdge, (kNear + kFar) / 2, 0));
}

// The depth of a point found after the stereo matching (a corner followed by Lucas-Kanade) is kept only when
// clean: on either surface of the same depth edge it is that surface's; across the edge there is none.
TEST(Stereo, CleanRowDepthRefusesAWindowAcrossADepthEdge)
{
	constexpr int kEdge = 100, kFar = 11, kNear = 14;
	const std::pair<cv::Mat, cv::Mat> pair = depth_edge_pair(kEdge, kFar, kNear);
	const cv::Mat &left = pair.first, &right = pair.second;
	StereoParams params;
	params.min_disparity_px = 2;
	params.max_disparity_px = 40;
	RowSearchBuffers buffers;
	const auto near_point = clean_row_depth(left, right, {60, 50}, kRig, params, buffers);
	ASSERT_TRUE(near_point.has_value());
	EXPECT_NEAR((*near_point)[2], kRig.depth(kNear), kRig.depth(kNear) * 0.01);
	const auto far_point = clean_row_depth(left, right, {150, 50}, kRig, params, buffers);
	ASSERT_TRUE(far_point.has_value());
	EXPECT_NEAR((*far_point)[2], kRig.depth(kFar), kRig.depth(kFar) * 0.01);
	EXPECT_NEAR((*far_point)[0], (150 - kRig.cx) * (*far_point)[2] / kRig.fx, 1e-3);
	EXPECT_FALSE(clean_row_depth(left, right, {kEdge, 50}, kRig, params, buffers).has_value());
	const cv::Mat flat(100, 200, CV_8UC1, cv::Scalar(90));
	EXPECT_FALSE(clean_row_depth(flat, flat, {60, 50}, kRig, params, buffers).has_value());
	// Outside the disparity range there is no depth either.
	params.max_disparity_px = 10;
	EXPECT_FALSE(clean_row_depth(left, right, {60, 50}, kRig, params, buffers).has_value());
}

TEST(Stereo, MatchesConstructedPairAndMeasuresDepthAndRowHealth)
{
	const cv::Mat left = texture(640, 480, 5);
	const double d = 16.4; // 800 * 0.1 / 16.4 = 4.878 m
	const cv::Mat right = shifted(left, d);
	FeatureParams fp;
	fp.max_features = 500;
	const FrameFeatures lf = extract_features(left, fp, 1);
	const FrameFeatures rf = extract_features(right, fp, 1);
	const StereoDepth depth = match_stereo(lf, rf, left, right, kRig, StereoParams{}, fp.orb_scale);
	EXPECT_GT(depth.matched, 150);
	int within = 0;
	for (size_t i = 0; i < depth.disparity.size(); ++i) {
		if (std::isnan(depth.disparity[i]))
			continue;
		within += std::abs(depth.disparity[i] - d) < 0.25 ? 1 : 0;
		EXPECT_NEAR(depth.xyz[i][2], kRig.depth(depth.disparity[i]), 1e-3);
	}
	EXPECT_GT(within, depth.matched * 9 / 10);
	EXPECT_NEAR(median_of(depth.row_differences), 0, 0.1);
	EXPECT_LT(depth.outside_band, depth.candidates / 20 + 1);

	// A rig whose right camera dropped 2.3 rows: the row health shows it, and matches leave the band.
	cv::Mat dropped;
	cv::warpAffine(left, dropped, cv::Matx23d(1, 0, -d, 0, 1, 2.3), left.size(), cv::INTER_LINEAR,
		       cv::BORDER_REFLECT_101);
	const FrameFeatures df = extract_features(dropped, fp, 1);
	const StereoDepth bumped = match_stereo(lf, df, left, dropped, kRig, StereoParams{}, fp.orb_scale);
	EXPECT_GT(bumped.outside_band, bumped.candidates / 2);
	// The row search assumes the rows agree; 2.3 rows off, its correlation and two-way check refuse (0 here)
	// rather than give depths from the wrong row.
	EXPECT_LE(bumped.row_searched, 5);
	// The row search alone (the default between health frames) has next to nothing to measure the rig by:
	// too few matches for CalibrationHealth to take the frame.
	const StereoDepth rows_only =
		match_stereo(lf, FrameFeatures{}, left, dropped, kRig, StereoParams{}, fp.orb_scale);
	EXPECT_LT(rows_only.matched, 10);
}

TEST(Stereo, SearchesTheRowWhereTheRightEyeHasNoKeypoint)
{
	const cv::Mat left = texture(640, 480, 5);
	const double d = 16.4;
	const cv::Mat right = shifted(left, d);
	const StereoParams params;
	RowSearchBuffers buffers;
	for (const cv::Point2f p : {cv::Point2f(100, 100), cv::Point2f(320, 240), cv::Point2f(600, 400)})
		EXPECT_NEAR(search_row(left, right, p, params, buffers), d, 0.25) << p;
	// No answer where there is none: a flat window, stripes repeating every 8 px (every 8th disparity fits as
	// well), a window off the image.
	const cv::Mat flat(480, 640, CV_8U, cv::Scalar(90));
	EXPECT_TRUE(std::isnan(search_row(flat, flat, {320, 240}, params, buffers)));
	cv::Mat stripes(480, 640, CV_8U);
	for (int x = 0; x < stripes.cols; ++x)
		stripes.col(x).setTo(x % 8 < 4 ? 200 : 50);
	EXPECT_TRUE(std::isnan(search_row(stripes, shifted(stripes, 5), {320, 240}, params, buffers)));
	EXPECT_TRUE(std::isnan(search_row(left, right, {3, 240}, params, buffers)));

	// The right eye's detector missed every corner left of x = 320: those left points get their depth from
	// the row search (and only with it).
	FeatureParams fp;
	fp.max_features = 500;
	const FrameFeatures lf = extract_features(left, fp, 1);
	const FrameFeatures all_right = extract_features(right, fp, 1);
	FrameFeatures rf = all_right;
	rf.keypoints.clear();
	rf.descriptors = cv::Mat();
	for (size_t j = 0; j < all_right.keypoints.size(); ++j)
		if (all_right.keypoints[j].pt.x >= 320) {
			rf.keypoints.push_back(all_right.keypoints[j]);
			rf.descriptors.push_back(all_right.descriptors.row(static_cast<int>(j)));
		}
	const auto left_half_with_depth = [&](const StereoDepth &depth) {
		int with = 0, right_value = 0;
		for (size_t i = 0; i < lf.keypoints.size(); ++i)
			if (lf.keypoints[i].pt.x < 320 - d - 8 && !std::isnan(depth.disparity[i])) {
				++with;
				right_value += std::abs(depth.disparity[i] - d) < 0.25 ? 1 : 0;
			}
		return std::pair{with, right_value};
	};
	StereoParams descriptors_only;
	descriptors_only.row_search = false;
	const StereoDepth without = match_stereo(lf, rf, left, right, kRig, descriptors_only, fp.orb_scale);
	EXPECT_EQ(left_half_with_depth(without).first, 0);
	EXPECT_EQ(without.row_searched, 0);
	const StereoDepth with = match_stereo(lf, rf, left, right, kRig, params, fp.orb_scale);
	const auto [found, right_values] = left_half_with_depth(with);
	EXPECT_GT(found, 100);
	EXPECT_GT(right_values, found * 9 / 10);
	EXPECT_GE(with.row_searched, found);
	EXPECT_EQ(with.matched, without.matched + with.row_searched);

	// No right features at all (stereo.right_features = false): every depth from the row search, and its
	// row offsets still show a rig whose right camera dropped 0.6 rows.
	const StereoDepth rows_only = match_stereo(lf, FrameFeatures{}, left, right, kRig, params, fp.orb_scale);
	EXPECT_GT(rows_only.matched, static_cast<int>(lf.keypoints.size()) * 8 / 10);
	EXPECT_EQ(rows_only.row_searched, rows_only.matched);
	EXPECT_NEAR(median_of(rows_only.row_differences), 0, 0.1);
	cv::Mat dropped;
	cv::warpAffine(left, dropped, cv::Matx23d(1, 0, -d, 0, 1, 0.6), left.size(), cv::INTER_LINEAR,
		       cv::BORDER_REFLECT_101);
	const StereoDepth bumped = match_stereo(lf, FrameFeatures{}, left, dropped, kRig, params, fp.orb_scale);
	EXPECT_GT(bumped.matched, 100);
	EXPECT_NEAR(median_of(bumped.row_differences), -0.6, 0.15);
}

TEST(Matching, LucasKanadeRefinesToSubpixel)
{
	const cv::Mat prev = texture(320, 240, 9);
	cv::Mat cur;
	cv::warpAffine(prev, cur, cv::Matx23d(1, 0, 3.4, 0, 1, -1.7), prev.size(), cv::INTER_LINEAR,
		       cv::BORDER_REFLECT_101);
	const std::vector<cv::Point2f> from = {{100, 100}, {200, 150}, {60, 180}};
	std::vector<cv::Point2f> to = {{103, 98}, {203, 148}, {63, 178}}; // keypoint positions, whole pixels
	FrameFeatures a, b;
	a.grey = prev;
	b.grey = cur;
	const std::vector<cv::Point2f> start = to;
	EXPECT_EQ(refine_matches(a, b, from, to, MatchParams{}), 3);
	for (size_t i = 0; i < from.size(); ++i) {
		EXPECT_NEAR(to[i].x - from[i].x, 3.4, 0.08);
		EXPECT_NEAR(to[i].y - from[i].y, -1.7, 0.08);
	}
	// On the pyramids the extract stage builds, the same positions.
	a.grey_pyramid = lk_pyramid(a.grey, MatchParams{});
	b.grey_pyramid = lk_pyramid(b.grey, MatchParams{});
	std::vector<cv::Point2f> again = start;
	EXPECT_EQ(refine_matches(a, b, from, again, MatchParams{}), 3);
	for (size_t i = 0; i < from.size(); ++i)
		EXPECT_EQ(again[i], to[i]);
}

TEST(Stereo, CalibrationHealthWarnsPastHalfAPixel)
{
	CalibrationHealth health(30);
	StereoSummary good{500, 300, 320, 4, 0.05F};
	for (int i = 0; i < 40; ++i)
		health.add(good);
	EXPECT_FALSE(health.drifted());
	EXPECT_NEAR(health.row_diff_px(), 0.05, 1e-6);
	EXPECT_NEAR(health.outside_band_fraction(), 4.0 / 320, 1e-9);
	StereoSummary bumped{500, 200, 320, 150, -0.9F};
	for (int i = 0; i < 60; ++i)
		health.add(bumped);
	EXPECT_TRUE(health.drifted());
	EXPECT_LT(health.row_diff_px(), -0.5);
	// Frames with too few matches say nothing about the rig.
	const uint64_t before = health.frames();
	health.add(StereoSummary{500, 3, 5, 0, 4.0F});
	EXPECT_EQ(health.frames(), before);
}

TEST(Stereo, RowSearchAloneMatchesTheRightFeaturesEveryFewFramesForTheRigsHealth)
{
	StereoParams params; // the default: the row search alone, descriptors every 30th frame
	EXPECT_FALSE(params.right_features);
	EXPECT_TRUE(right_features_wanted(params, 0));
	EXPECT_FALSE(right_features_wanted(params, 1));
	EXPECT_FALSE(right_features_wanted(params, 29));
	EXPECT_TRUE(right_features_wanted(params, 60));
	params.health_every_frames = 0;
	EXPECT_FALSE(right_features_wanted(params, 0));
	params.right_features = true;
	EXPECT_TRUE(right_features_wanted(params, 7));

	// A rig bumped by 2.3 rows: the row search's few survivors sit on vertical edges and measure no offset,
	// the descriptor frames measure the bump. Once descriptor frames are seen, only they count.
	CalibrationHealth health(30);
	const StereoSummary rows_only{500, 40, 0, 0, 0.0F};
	const StereoSummary descriptors{500, 200, 320, 150, -2.3F};
	for (int second = 0; second < 40; ++second) {
		health.add(descriptors);
		for (int i = 1; i < 30; ++i)
			health.add(rows_only);
	}
	EXPECT_TRUE(health.drifted());
	EXPECT_NEAR(health.row_diff_px(), -2.3, 1e-6);
	EXPECT_NEAR(health.outside_band_fraction(), 150.0 / 320, 1e-9);
	EXPECT_EQ(health.frames(), 40U);

	// Without descriptor frames the row search's offsets are all there is (a 0.6-row drop still shows).
	CalibrationHealth rows_alone(30);
	for (int i = 0; i < 40; ++i)
		rows_alone.add(StereoSummary{500, 300, 0, 0, -0.6F});
	EXPECT_TRUE(rows_alone.drifted());
	EXPECT_DOUBLE_EQ(rows_alone.outside_band_fraction(), 0);
}

namespace {

/// Runs a track through advance_anchor frame by frame at 30 fps, as the pair stage does (the track ages by
/// one each frame); depths[n] < 0: no depth in frame n. The camera is at z = camera_step_m * n.
std::vector<AnchorTest> anchor_tests(const std::vector<double> &depths, double sigma_m, double camera_step_m,
				     const AnchorParams &params)
{
	TrackState state;
	std::vector<AnchorTest> out;
	for (size_t n = 0; n < depths.size(); ++n) {
		if (n > 0)
			++state.anchor_age;
		geometry::Pose world_from_camera;
		world_from_camera.t = {0, 0, camera_step_m * static_cast<double>(n)};
		std::optional<DepthSample> depth;
		if (depths[n] > 0)
			depth = DepthSample{cv::Vec3d(0.5, 0.2, depths[n]), sigma_m};
		out.push_back(advance_anchor(state, depth, true, static_cast<int64_t>(n) * 33'333'333,
					     CameraInWorld(world_from_camera), params));
	}
	return out;
}

/// The statistics of anchor_tests alone.
std::vector<double> anchor_statistics(const std::vector<double> &depths, double sigma_m, double camera_step_m,
				      const AnchorParams &params)
{
	std::vector<double> out;
	for (const AnchorTest &test : anchor_tests(depths, sigma_m, camera_step_m, params))
		out.push_back(test.statistic);
	return out;
}

} // namespace

// The anchor over a track's life, by hand. A walker coming 4 cm a frame nearer from 10 m (sigma 5 cm): the
// anchor is the mean of frames 0-5 (9.90 m, sigma sqrt(6 x 0.05^2) / 6 = 0.0204 m), so at frame 6 (9.76 m) the
// statistic is 0.14^2 / (0.0204^2 + 0.05^2) = 6.72 and it grows as the walker comes on; a still point seen by a
// camera walking 5 cm a frame stays at 0.
TEST(Geometry, AnchorAveragesThenTestsADrift)
{
	const AnchorParams params; // min 6 frames, 3 m/s, gate 6.63
	std::vector<double> walker, still;
	for (int n = 0; n < 12; ++n) {
		walker.push_back(10.0 - 0.04 * n);
		still.push_back(10.0 - 0.05 * n);
	}
	const auto w = anchor_statistics(walker, 0.05, 0, params);
	for (int n = 0; n < 6; ++n)
		EXPECT_TRUE(std::isnan(w[static_cast<size_t>(n)])) << n; // warming up
	EXPECT_NEAR(w[6], 0.14 * 0.14 / (0.05 * 0.05 / 6 + 0.05 * 0.05), 1e-3);
	EXPECT_NEAR(w[11], 0.34 * 0.34 / (0.05 * 0.05 / 6 + 0.05 * 0.05), 1e-3); // 0.34 m off: 39.6
	const auto s = anchor_statistics(still, 0.05, 0.05, params);
	for (int n = 6; n < 12; ++n)
		EXPECT_NEAR(s[static_cast<size_t>(n)], 0, 1e-6) << n;
}

// The pooled test's signed drift, by hand. The same walker (4 cm a frame nearer from 10 m, sigma 5 cm), with the
// drift measured once the anchor holds 3 depths: at frame 3 the anchor is the mean of frames 0-2 (9.96 m, sigma
// 0.05 / sqrt(3)) and the depth 9.88 m, so the drift is +0.08 / sqrt(0.05^2 / 3 + 0.05^2) = +1.386 sigmas, under
// any single point's gate; at frame 8 the anchor is the mean of frames 0-5 (9.90 m) and the depth 9.68 m: +3.81.
// A point moving away drifts negative, a still one not at all.
TEST(Geometry, AnchorMeasuresASignedDriftForThePooledTest)
{
	AnchorParams params;
	params.pool_samples = 3;
	std::vector<double> toward, away, still;
	for (int n = 0; n < 10; ++n) {
		toward.push_back(10.0 - 0.04 * n);
		away.push_back(10.0 + 0.04 * n);
		still.push_back(10.0 - 0.05 * n);
	}
	const auto t = anchor_tests(toward, 0.05, 0, params);
	for (size_t n = 0; n < 3; ++n)
		EXPECT_TRUE(std::isnan(t[n].drift_sigmas)) << n;
	EXPECT_NEAR(t[3].drift_sigmas, 0.08 / std::sqrt(0.05 * 0.05 / 3 + 0.05 * 0.05), 1e-4);
	EXPECT_NEAR(t[8].drift_sigmas, 0.22 / std::sqrt(0.05 * 0.05 / 6 + 0.05 * 0.05), 1e-4);
	EXPECT_NEAR(t[8].statistic, t[8].drift_sigmas * t[8].drift_sigmas, 1e-3); // the anchored test's (in floats)
	EXPECT_NEAR(anchor_tests(away, 0.05, 0, params)[8].drift_sigmas, -t[8].drift_sigmas, 1e-4);
	const auto s = anchor_tests(still, 0.05, 0.05, params);
	for (size_t n = 3; n < s.size(); ++n)
		EXPECT_NEAR(s[n].drift_sigmas, 0, 1e-6) << n;
	// Off: no drift measured.
	EXPECT_TRUE(std::isnan(anchor_tests(toward, 0.05, 0, AnchorParams{})[8].drift_sigmas));
}

// Ten points on a walker at 9 m, each drifting +1.3 sigmas (no single one near the 2.58 a point's own test needs):
// with the ground point beside them, (13 - 0.3) / sqrt(11) = 3.83 over the 3.5 gate, so all ten are found. Around them,
// the static scene at the same depth, its drifts alternating +-1.2, sums to nothing; a static point beside the walker
// whose own drift points the other way is counted but not taken along; the background 5 m behind is neither pooled with
// the walker nor, alone, found.
TEST(Geometry, PooledDriftFindsAMoverNoPointOfWhichDriftsPastItsOwnNoise)
{
	std::vector<cv::Point2f> px;
	std::vector<float> depth;
	std::vector<double> drift;
	const auto add = [&](float u, float v, float z, double d) {
		px.emplace_back(u, v);
		depth.push_back(z);
		drift.push_back(d);
	};
	for (int i = 0; i < 10; ++i) // the walker: 50 x 20 px
		add(500.0f + 10.0f * static_cast<float>(i % 5), 400.0f + 10.0f * static_cast<float>(i / 5), 9.0f, 1.3);
	const size_t ground = px.size();
	add(520, 425, 9.1f, -0.3); // the ground at the walker's feet
	const size_t behind = px.size();
	add(490, 395, 14.0f, 3.0); // the wall behind, beside the walker in the image
	const size_t first_static = px.size();
	for (int i = 0; i < 40; ++i) // the static scene at the walker's depth, away from it
		add(100.0f + 15.0f * static_cast<float>(i % 10), 100.0f + 15.0f * static_cast<float>(i / 10), 9.0f,
		    i % 2 == 0 ? 1.2 : -1.2);
	DriftPoolParams params; // 80 px, 5 % of the depth, 4 points, 3.5 sigmas (2.0 to hold), own 0.5
	const std::vector<uint8_t> found = pool_depth_drift(px, depth, drift, {}, params);
	ASSERT_EQ(found.size(), px.size());
	for (size_t i = 0; i < ground; ++i)
		EXPECT_EQ(found[i], 1) << i;
	EXPECT_EQ(found[ground], 0);
	EXPECT_EQ(found[behind], 0);
	for (size_t i = first_static; i < px.size(); ++i)
		EXPECT_EQ(found[i], 0) << i;
	// A walker found in the frames before holds at the lower gate (2.0): at +0.8 sigmas a point the sum is
	// (8 - 0.3) / sqrt(11) = 2.32, not enough to be found afresh, enough to stay found.
	for (size_t i = 0; i < ground; ++i)
		drift[i] = 0.8;
	const std::vector<uint8_t> afresh = pool_depth_drift(px, depth, drift, {}, params);
	std::vector<uint8_t> held(px.size(), 0);
	std::fill(held.begin(), held.begin() + static_cast<std::ptrdiff_t>(ground), uint8_t{1});
	const std::vector<uint8_t> holding = pool_depth_drift(px, depth, drift, held, params);
	for (size_t i = 0; i < ground; ++i) {
		EXPECT_EQ(afresh[i], 0) << i;
		EXPECT_EQ(holding[i], 1) << i;
	}
	// Fewer than min_points with a drift: nothing, however far they drift.
	params.min_points = 12;
	const std::vector<uint8_t> too_few = pool_depth_drift(px, depth, drift, {}, params);
	EXPECT_EQ(std::count(too_few.begin(), too_few.begin() + static_cast<std::ptrdiff_t>(ground), 1), 0);
}

// A track that passes from a mover (12 m) onto the background behind it (14 m) leaps 2 m in a frame, far
// more than 3 m/s allows: its anchor starts again at 14 m instead of failing the still background for the
// next 90 frames; without the leap check it fails at once. A leap after frames without depth is judged
// against the last depth and the time since.
TEST(Geometry, ADepthLeapStartsTheAnchorAgain)
{
	std::vector<double> depths(20, 12.0);
	for (size_t n = 8; n < depths.size(); ++n)
		depths[n] = 14.0;
	AnchorParams params;
	const auto with_check = anchor_statistics(depths, 0.1, 0, params);
	EXPECT_NEAR(with_check[7], 0, 1e-6);
	for (size_t n = 8; n < 14; ++n)
		EXPECT_TRUE(std::isnan(with_check[n])) << n; // anchored again at frame 8, warming up to 13
	for (size_t n = 14; n < depths.size(); ++n)
		EXPECT_NEAR(with_check[n], 0, 1e-6) << n;
	params.max_speed_mps = 0;
	const auto without = anchor_statistics(depths, 0.1, 0, params);
	EXPECT_GT(without[8], 100);

	std::vector<double> gap = depths;
	gap[8] = gap[9] = gap[10] = -1; // no depth for three frames, then 14 m: 2 m in 4 frames, > 3 m/s x 0.13 s
	const auto after_gap = anchor_statistics(gap, 0.1, 0, AnchorParams{});
	EXPECT_TRUE(std::isnan(after_gap[11]));
	EXPECT_NEAR(after_gap[17], 0, 1e-6);
	// A walker at 1.2 m/s is no leap.
	std::vector<double> walker;
	for (int n = 0; n < 12; ++n)
		walker.push_back(10.0 - 0.04 * n);
	EXPECT_FALSE(std::isnan(anchor_statistics(walker, 0.05, 0, AnchorParams{})[11]));
}

TEST(Geometry, AnchoredFindsSpreadToYoungTracksAtTheSameDepth)
{
	// Two points the test found on a walker at 5 m; beside them young tracks: one at 5.1 m 20 px away (both
	// found within 40 px and 5 %: dynamic), one at 5.6 m (the ground behind: 10 % deeper, stays), one at 5 m
	// 30 px from the second find but 51 px from the first (one within reach: stays), one at 5 m with its own track
	// already tested (not open: stays), one without depth (stays).
	const std::vector<cv::Point2f> px = {{100, 100}, {120, 110}, {110, 120}, {115, 125},
					     {150, 110}, {105, 105}, {112, 108}};
	const float none = std::numeric_limits<float>::quiet_NaN();
	const std::vector<float> depth = {5.0F, 5.0F, 5.1F, 5.6F, 5.0F, 5.0F, none};
	const std::vector<uint8_t> found = {1, 1, 0, 0, 0, 0, 0};
	const std::vector<uint8_t> open = {0, 0, 1, 1, 1, 0, 1};
	const DepthSpreadParams params{40, 0.05, 2};
	EXPECT_EQ(spread_by_depth(px, depth, found, open, params), (std::vector<uint8_t>{0, 0, 1, 0, 0, 0, 0}));
	// One find is not enough for two; it is for one. Off with a zero radius.
	const std::vector<uint8_t> one_found = {1, 0, 0, 0, 0, 0, 0};
	EXPECT_EQ(spread_by_depth(px, depth, one_found, open, params), std::vector<uint8_t>(7, 0));
	const std::vector<uint8_t> all_young = {0, 1, 1, 1, 1, 0, 1};
	EXPECT_EQ(spread_by_depth(px, depth, one_found, all_young, DepthSpreadParams{40, 0.05, 1}),
		  (std::vector<uint8_t>{0, 1, 1, 0, 0, 0, 0}));
	EXPECT_EQ(spread_by_depth(px, depth, found, open, DepthSpreadParams{0, 0.05, 2}), std::vector<uint8_t>(7, 0));
}

TEST(Geometry, AnchoredDepthByHand)
{
	// A point anchored 6 m ahead (sigma 0.1 m); the camera walked 0.5 m forward since: a static point is now
	// at 5.5 m. Measured 5.5: statistic 0. Measured 5.0 with sigma 0.1: (0.5)^2 / (0.01 + 0.01) = 12.5.
	geometry::Pose camera_from_world;
	camera_from_world.t = {0, 0, -0.5};
	const cv::Vec3f anchor(0.4F, 0.2F, 6.0F);
	EXPECT_NEAR(anchored_depth_statistic(anchor, 0.1F, camera_from_world, 5.5F, 0.1), 0, 1e-9);
	EXPECT_NEAR(anchored_depth_statistic(anchor, 0.1F, camera_from_world, 5.0F, 0.1), 12.5, 1e-4);
	EXPECT_TRUE(std::isnan(anchored_depth_statistic(cv::Vec3f(NAN, 0, 0), 0.1F, camera_from_world, 5.0F, 0.1)));
	EXPECT_TRUE(std::isnan(anchored_depth_statistic(anchor, 0.1F, camera_from_world, NAN, 0.1)));
}
