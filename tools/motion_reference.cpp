#include "tools/motion_reference.hpp"

#include <algorithm>
#include <stdexcept>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace stereod::tools {

cv::Mat median_background(std::span<const cv::Mat> samples)
{
	if (samples.empty())
		throw std::invalid_argument("median_background: no samples");
	const cv::Mat &first = samples.front();
	if (first.depth() != CV_8U)
		throw std::invalid_argument("median_background: 8-bit images only");
	for (const cv::Mat &s : samples)
		if (s.size() != first.size() || s.type() != first.type())
			throw std::invalid_argument("median_background: samples differ in size or type");
	cv::Mat background(first.size(), first.type());
	std::vector<uint8_t> column(samples.size());
	std::vector<const uint8_t *> rows(samples.size());
	for (int y = 0; y < first.rows; ++y) {
		for (size_t k = 0; k < samples.size(); ++k)
			rows[k] = samples[k].ptr<uint8_t>(y);
		uint8_t *out = background.ptr<uint8_t>(y);
		const int width = first.cols * first.channels();
		for (int x = 0; x < width; ++x) {
			for (size_t k = 0; k < samples.size(); ++k)
				column[k] = rows[k][x];
			const auto mid = column.begin() + static_cast<std::ptrdiff_t>(column.size() / 2);
			std::nth_element(column.begin(), mid, column.end());
			out[x] = *mid;
		}
	}
	return background;
}

cv::Mat mover_mask(const cv::Mat &frame, const cv::Mat &background, const MotionReferenceParams &params)
{
	if (frame.size() != background.size() || frame.type() != background.type())
		throw std::invalid_argument("mover_mask: frame and background differ in size or type");
	cv::Mat diff;
	cv::absdiff(frame, background, diff);
	if (diff.channels() > 1) {
		std::vector<cv::Mat> channels;
		cv::split(diff, channels);
		diff = channels[0];
		for (size_t c = 1; c < channels.size(); ++c)
			diff = cv::max(diff, channels[c]);
	}
	cv::Mat moving = diff > params.threshold;
	// Opening removes single-pixel noise; closing joins the parts of a body (a shirt the colour of the
	// pavement differs from it only at its edges).
	cv::morphologyEx(moving, moving, cv::MORPH_OPEN, cv::getStructuringElement(cv::MORPH_ELLIPSE, {3, 3}));
	if (params.close_radius_px > 0) {
		const int k = 2 * params.close_radius_px + 1;
		cv::morphologyEx(moving, moving, cv::MORPH_CLOSE, cv::getStructuringElement(cv::MORPH_ELLIPSE, {k, k}));
	}
	cv::Mat labels, stats, centroids;
	const int count = cv::connectedComponentsWithStats(moving, labels, stats, centroids, 8, CV_32S);
	std::vector<uint8_t> id_of(static_cast<size_t>(count), 0);
	int next = 0;
	for (int c = 1; c < count && next < 255; ++c)
		if (stats.at<int>(c, cv::CC_STAT_AREA) >= params.min_area_px)
			id_of[static_cast<size_t>(c)] = static_cast<uint8_t>(++next);
	cv::Mat mask(frame.size(), CV_8UC1, cv::Scalar(0));
	for (int y = 0; y < mask.rows; ++y) {
		const int *l = labels.ptr<int>(y);
		uint8_t *m = mask.ptr<uint8_t>(y);
		for (int x = 0; x < mask.cols; ++x)
			m[x] = id_of[static_cast<size_t>(l[x])];
	}
	if (params.dilate_radius_px > 0) {
		const int k = 2 * params.dilate_radius_px + 1;
		cv::dilate(mask, mask, cv::getStructuringElement(cv::MORPH_RECT, {k, k}));
	}
	return mask;
}

} // namespace stereod::tools
