#pragma once
// The picture v4l2_feed writes into v4l2loopback and v4l2_check expects: a side-by-side grey image whose
// left and right halves differ, so a swapped or shifted eye is caught. The pattern is smooth (a gentle ramp
// folded at 0 and 255, not wrapped), so that a JPEG of it decodes within a few levels everywhere.
#include <cstdint>
#include <cstdlib>

#include <opencv2/core.hpp>

namespace stereod::v4l2test {

inline uint8_t pattern_value(int x, int y, bool right) noexcept
{
	const int v = (3 * x + 7 * y + (right ? 128 : 0)) % 510; // up 0..254, then down 255..1: no jumps
	return static_cast<uint8_t>(v < 255 ? v : 509 - v);
}

/// Pixels of the two eyes more than `tolerance` off the pattern (0: any difference; a JPEG's rounding needs a
/// few levels, a swapped or shifted eye is off by far more almost everywhere).
inline int count_mismatches(const cv::Mat &left, const cv::Mat &right, int tolerance = 0)
{
	int bad = 0;
	for (int y = 0; y < left.rows; ++y)
		for (int x = 0; x < left.cols; ++x) {
			bad += std::abs(left.at<uint8_t>(y, x) - pattern_value(x, y, false)) > tolerance;
			bad += std::abs(right.at<uint8_t>(y, x) - pattern_value(x, y, true)) > tolerance;
		}
	return bad;
}

} // namespace stereod::v4l2test
