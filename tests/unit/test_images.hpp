#pragma once
// Constructed images the unit tests share.
#include <cstdint>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace stereod::test {

/// Smoothed noise, stretched to 0-255 (one channel): corners and texture at every scale Lucas-Kanade, DIS and ORB
/// look at, and no repeated pattern.
inline cv::Mat smoothed_noise(cv::Size size, uint64_t seed, double sigma)
{
	cv::Mat noise(size, CV_8U);
	cv::RNG rng(seed);
	rng.fill(noise, cv::RNG::UNIFORM, 0, 256);
	cv::Mat smooth;
	cv::GaussianBlur(noise, smooth, cv::Size(0, 0), sigma);
	cv::normalize(smooth, smooth, 0, 255, cv::NORM_MINMAX);
	return smooth;
}

/// `image` moved by `by` pixels (bilinear; the border reflected).
inline cv::Mat shifted(const cv::Mat &image, cv::Point2f by)
{
	cv::Mat out;
	cv::warpAffine(image, out, cv::Matx23d(1, 0, by.x, 0, 1, by.y), image.size(), cv::INTER_LINEAR,
		       cv::BORDER_REFLECT);
	return out;
}

} // namespace stereod::test
