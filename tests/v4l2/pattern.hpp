#pragma once
// The picture v4l2_feed writes into v4l2loopback and v4l2_check expects: a side-by-side GREY image whose
// left and right halves differ, so a swapped or shifted eye is caught.
#include <cstdint>

#include <opencv2/core.hpp>

namespace stereod::v4l2test {

inline uint8_t pattern_value(int x, int y, bool right) noexcept
{
	return static_cast<uint8_t>((3 * x + 7 * y + (right ? 128 : 0)) & 0xff);
}

/// Pixels of the two eyes that differ from the pattern.
inline int count_mismatches(const cv::Mat &left, const cv::Mat &right)
{
	int bad = 0;
	for (int y = 0; y < left.rows; ++y)
		for (int x = 0; x < left.cols; ++x) {
			bad += left.at<uint8_t>(y, x) != pattern_value(x, y, false);
			bad += right.at<uint8_t>(y, x) != pattern_value(x, y, true);
		}
	return bad;
}

} // namespace stereod::v4l2test
