// This project's SURF on constructed images with known answers.
#include <gtest/gtest.h>

#include <numbers>

#include <opencv2/imgproc.hpp>

#include "core/vision/surf.hpp"

using namespace stereod::vision;

namespace {

/// A bright Gaussian blob of standard deviation sigma on a grey background.
cv::Mat blob_image(cv::Point2f centre, double sigma, cv::Size size = {200, 200})
{
	cv::Mat image(size, CV_32F, cv::Scalar(60));
	for (int y = 0; y < size.height; ++y)
		for (int x = 0; x < size.width; ++x) {
			const double d2 = (x - centre.x) * (x - centre.x) + (y - centre.y) * (y - centre.y);
			image.at<float>(y, x) += static_cast<float>(150 * std::exp(-d2 / (2 * sigma * sigma)));
		}
	cv::Mat out;
	image.convertTo(out, CV_8U);
	return out;
}

cv::Mat textured(int w, int h, uint64_t seed)
{
	cv::Mat noise(h, w, CV_8UC1);
	cv::RNG rng(seed);
	rng.fill(noise, cv::RNG::UNIFORM, 0, 256);
	cv::Mat out;
	cv::GaussianBlur(noise, out, cv::Size(0, 0), 2.0);
	cv::normalize(out, out, 0, 255, cv::NORM_MINMAX);
	return out;
}

} // namespace

TEST(Surf, IntegralBoxSums)
{
	cv::Mat image(4, 5, CV_8UC1);
	for (int i = 0; i < 20; ++i)
		image.data[i] = static_cast<uint8_t>(i);
	const cv::Mat ii = surf_integral(image);
	EXPECT_EQ(ii.rows, 5);
	EXPECT_EQ(ii.at<int>(4, 5), 190); // 0 + 1 + ... + 19
}

TEST(Surf, FindsABlobAtItsPositionAndScale)
{
	std::vector<double> ratios;
	for (double sigma : {2.5, 4.0, 6.0}) {
		const cv::Point2f centre(101.0F, 97.0F);
		const cv::Mat ii = surf_integral(blob_image(centre, sigma));
		SurfParams params;
		params.initial_step = 1;
		const auto kps = surf_detect(ii, params);
		ASSERT_FALSE(kps.empty()) << "sigma " << sigma;
		const auto best = std::max_element(
			kps.begin(), kps.end(), [](const auto &a, const auto &b) { return a.response < b.response; });
		EXPECT_LT(cv::norm(best->pt - centre), 1.5) << "sigma " << sigma;
		EXPECT_EQ(best->laplacian, -1) << "a bright blob has a negative Laplacian";
		ratios.push_back(best->scale / sigma);
	}
	// The scale follows the blob: the same ratio for every size. (Box filters put it at about 0.75 of the
	// Gaussian's sigma rather than 1; docs/classification.md gives the measured values.)
	for (double r : ratios) {
		EXPECT_GT(r, 0.6);
		EXPECT_LT(r, 1.05);
	}
	EXPECT_LT(*std::max_element(ratios.begin(), ratios.end()) / *std::min_element(ratios.begin(), ratios.end()),
		  1.2);
}

namespace {

/// Of the keypoints near the centre, how many find their own rotated copy as nearest descriptor.
std::pair<int, int> rotation_matches(bool upright)
{
	const cv::Mat image = textured(240, 240, 3);
	const cv::Mat rotation = cv::getRotationMatrix2D(cv::Point2f(120, 120), 40.0, 1.0);
	cv::Mat rotated;
	cv::warpAffine(image, rotated, rotation, image.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
	SurfParams params;
	params.upright = upright;
	const cv::Mat ii0 = surf_integral(image), ii1 = surf_integral(rotated);
	auto k0 = surf_detect(ii0, params), k1 = surf_detect(ii1, params);
	const cv::Mat d0 = surf_describe(ii0, k0, params), d1 = surf_describe(ii1, k1, params);
	int checked = 0, correct = 0;
	for (size_t i = 0; i < k0.size(); ++i) {
		if (cv::norm(k0[i].pt - cv::Point2f(120, 120)) > 70)
			continue; // stay clear of the rotated image's corners
		const cv::Matx23d a(rotation);
		const cv::Vec2d e = a * cv::Vec3d(k0[i].pt.x, k0[i].pt.y, 1.0);
		double best = 1e9;
		size_t best_j = 0;
		for (size_t j = 0; j < k1.size(); ++j) {
			const double d = cv::norm(d0.row(static_cast<int>(i)), d1.row(static_cast<int>(j)));
			if (d < best) {
				best = d;
				best_j = j;
			}
		}
		++checked;
		correct += cv::norm(cv::Point2d(k1[best_j].pt) - cv::Point2d(e[0], e[1])) < 3.0;
	}
	return {correct, checked};
}

} // namespace

TEST(Surf, DescriptorsSurviveRotation)
{
	const auto [correct, checked] = rotation_matches(false);
	ASSERT_GT(checked, 20);
	// Chance would be about 1 in a hundred; a rotation-invariant descriptor finds most.
	EXPECT_GE(correct, checked * 4 / 10) << correct << " of " << checked;
	const auto [upright_correct, upright_checked] = rotation_matches(true);
	EXPECT_LT(upright_correct * checked, correct * upright_checked)
		<< "without orientation (U-SURF) a 40 degree rotation must hurt: " << upright_correct << " of "
		<< upright_checked;
}

TEST(Surf, UprightSkipsOrientationAndExtendedDoublesTheLength)
{
	const cv::Mat ii = surf_integral(textured(160, 160, 4));
	SurfParams params;
	params.upright = true;
	params.extended = true;
	auto kps = surf_detect(ii, params);
	ASSERT_FALSE(kps.empty());
	const cv::Mat d = surf_describe(ii, kps, params);
	EXPECT_EQ(d.cols, 128);
	for (const auto &kp : kps)
		EXPECT_EQ(kp.orientation, 0.0F);
	for (int i = 0; i < d.rows; ++i)
		EXPECT_NEAR(cv::norm(d.row(i)), 1.0, 1e-4);
}

TEST(Surf, MaxFeaturesKeepsTheStrongest)
{
	const cv::Mat ii = surf_integral(textured(200, 200, 5));
	SurfParams all;
	auto every = surf_detect(ii, all);
	SurfParams some;
	some.max_features = 10;
	auto strongest = surf_detect(ii, some);
	ASSERT_EQ(strongest.size(), 10U);
	std::sort(every.begin(), every.end(), [](const auto &a, const auto &b) { return a.response > b.response; });
	const float tenth = every[9].response;
	for (const auto &kp : strongest)
		EXPECT_GE(kp.response, tenth);
}
