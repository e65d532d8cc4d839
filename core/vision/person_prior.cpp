#include "core/vision/person_prior.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>
#include <opencv2/objdetect.hpp>

namespace stereod::vision {

namespace {

float median_in_place(std::vector<float> &v)
{
	const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
	std::nth_element(v.begin(), mid, v.end());
	return *mid;
}

} // namespace

std::vector<PriorRegion> detect_people(const cv::Mat &grey, const PersonPriorParams &params)
{
	std::vector<PriorRegion> regions;
	if (grey.empty())
		return regions;
	// The descriptor is a few kilobytes of SVM weights: made per call, so the stage holds no state and any
	// worker may run it.
	cv::HOGDescriptor hog;
	hog.setSVMDetector(cv::HOGDescriptor::getDefaultPeopleDetector());
	cv::Mat image = grey;
	if (params.upscale != 1.0)
		cv::resize(grey, image, cv::Size(), params.upscale, params.upscale, cv::INTER_LINEAR);
	if (image.cols < hog.winSize.width || image.rows < hog.winSize.height)
		return regions;
	std::vector<cv::Rect> found;
	std::vector<double> weights;
	// hit threshold 0 (the SVM's own boundary), 8 px window stride, 1.05 between pyramid levels, windows
	// grouped when at least 2 overlap (OpenCV's defaults; a lone window is usually texture).
	hog.detectMultiScale(image, found, weights, 0, cv::Size(8, 8), cv::Size(), 1.05, 2);
	const auto scale = static_cast<float>(1.0 / params.upscale);
	const cv::Rect2f frame(0, 0, static_cast<float>(grey.cols), static_cast<float>(grey.rows));
	for (size_t i = 0; i < found.size(); ++i) {
		const double score = i < weights.size() ? weights[i] : 0.0;
		if (score < params.min_score)
			continue;
		cv::Rect2f box(static_cast<float>(found[i].x) * scale, static_cast<float>(found[i].y) * scale,
			       static_cast<float>(found[i].width) * scale, static_cast<float>(found[i].height) * scale);
		const auto mx = static_cast<float>(params.margin) * box.width;
		const auto my = static_cast<float>(params.margin) * box.height;
		box = cv::Rect2f(box.x - mx, box.y - my, box.width + 2 * mx, box.height + 2 * my) & frame;
		if (box.area() <= 0)
			continue;
		PriorRegion region;
		region.box = box;
		region.score = static_cast<float>(score);
		regions.push_back(std::move(region));
	}
	return regions;
}

std::vector<PriorRegion> carry_regions(std::span<const PriorRegion> regions, std::span<const cv::Point2f> from,
				       std::span<const cv::Point2f> to, int max_age_frames)
{
	std::vector<PriorRegion> carried;
	std::vector<float> dx, dy;
	for (const PriorRegion &region : regions) {
		if (region.age_frames + 1 > max_age_frames)
			continue;
		dx.clear();
		dy.clear();
		for (size_t i = 0; i < from.size() && i < to.size(); ++i) {
			if (!region_contains(region, from[i]))
				continue;
			dx.push_back(to[i].x - from[i].x);
			dy.push_back(to[i].y - from[i].y);
		}
		PriorRegion next = region;
		next.age_frames = region.age_frames + 1;
		if (!dx.empty()) {
			next.box.x += median_in_place(dx);
			next.box.y += median_in_place(dy);
		}
		carried.push_back(next);
	}
	return carried;
}

bool region_contains(const PriorRegion &region, cv::Point2f point)
{
	if (!region.box.contains(point))
		return false;
	if (region.mask.empty())
		return true;
	const int x = static_cast<int>(std::floor(point.x - region.box.x));
	const int y = static_cast<int>(std::floor(point.y - region.box.y));
	return x >= 0 && y >= 0 && x < region.mask.cols && y < region.mask.rows && region.mask.at<uint8_t>(y, x) != 0;
}

std::vector<uint8_t> in_dynamic_category(std::span<const cv::Point2f> points, std::span<const PriorRegion> regions)
{
	std::vector<uint8_t> inside(points.size(), 0);
	for (const PriorRegion &region : regions) {
		if (region.category != PriorCategory::Dynamic)
			continue;
		for (size_t i = 0; i < points.size(); ++i)
			if (region_contains(region, points[i]))
				inside[i] = 1;
	}
	return inside;
}

int vote_potentially_dynamic(std::span<const cv::Point2f> points, std::span<const PriorRegion> regions,
			     std::span<PointLabel> labels, double min_share)
{
	int changed = 0;
	const size_t n = std::min(points.size(), labels.size());
	for (const PriorRegion &region : regions) {
		if (region.category != PriorCategory::PotentiallyDynamic)
			continue;
		int decided = 0;
		int dynamic = 0;
		for (size_t i = 0; i < n; ++i) {
			if (labels[i] == PointLabel::Uncertain || !region_contains(region, points[i]))
				continue;
			++decided;
			dynamic += labels[i] == PointLabel::Dynamic ? 1 : 0;
		}
		if (dynamic < 2 || static_cast<double>(dynamic) < min_share * static_cast<double>(decided))
			continue;
		for (size_t i = 0; i < n; ++i)
			if (labels[i] != PointLabel::Dynamic && region_contains(region, points[i])) {
				labels[i] = PointLabel::Dynamic;
				++changed;
			}
	}
	return changed;
}

} // namespace stereod::vision
