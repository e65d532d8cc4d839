#include "core/vision/features.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

namespace stereod::vision {

cv::Vec3f sample_colour(const cv::Mat &image, cv::Point2f at, int radius)
{
	if (image.empty() || !std::isfinite(at.x) || !std::isfinite(at.y))
		return cv::Vec3f::all(std::numeric_limits<float>::quiet_NaN());
	radius = std::max(radius, 0);
	const int cx = std::clamp(cvRound(at.x), 0, image.cols - 1);
	const int cy = std::clamp(cvRound(at.y), 0, image.rows - 1);
	const int x0 = std::max(cx - radius, 0), x1 = std::min(cx + radius, image.cols - 1);
	const int y0 = std::max(cy - radius, 0), y1 = std::min(cy + radius, image.rows - 1);
	cv::Vec3f sum(0, 0, 0);
	if (image.type() == CV_8UC3) {
		for (int y = y0; y <= y1; ++y) {
			const auto *row = image.ptr<cv::Vec3b>(y);
			for (int x = x0; x <= x1; ++x)
				sum += cv::Vec3f(row[x][0], row[x][1], row[x][2]);
		}
	} else {
		for (int y = y0; y <= y1; ++y) {
			const auto *row = image.ptr<uint8_t>(y);
			for (int x = x0; x <= x1; ++x)
				sum += cv::Vec3f(row[x], row[x], row[x]);
		}
	}
	return sum / static_cast<float>((x1 - x0 + 1) * (y1 - y0 + 1));
}

std::vector<cv::KeyPoint> bucket_keypoints(std::vector<cv::KeyPoint> keypoints, cv::Size image_size, int grid_cols,
					   int grid_rows, int max_total)
{
	if (image_size.width <= 0 || image_size.height <= 0 || max_total <= 0)
		return {};
	grid_cols = std::max(grid_cols, 1);
	grid_rows = std::max(grid_rows, 1);
	const int cells = grid_cols * grid_rows;
	const int per_cell = std::max(max_total / cells, 1);
	std::vector<std::vector<cv::KeyPoint>> buckets(static_cast<size_t>(cells));
	for (const auto &kp : keypoints) {
		const int col = std::clamp(static_cast<int>(kp.pt.x * static_cast<float>(grid_cols) /
							    static_cast<float>(image_size.width)),
					   0, grid_cols - 1);
		const int row = std::clamp(static_cast<int>(kp.pt.y * static_cast<float>(grid_rows) /
							    static_cast<float>(image_size.height)),
					   0, grid_rows - 1);
		buckets[static_cast<size_t>(row * grid_cols + col)].push_back(kp);
	}
	const auto stronger = [](const cv::KeyPoint &a, const cv::KeyPoint &b) { return a.response > b.response; };
	std::vector<cv::KeyPoint> kept;
	kept.reserve(static_cast<size_t>(max_total));
	std::vector<cv::KeyPoint> spare;
	for (auto &bucket : buckets) {
		std::sort(bucket.begin(), bucket.end(), stronger);
		const auto take = std::min(bucket.size(), static_cast<size_t>(per_cell));
		kept.insert(kept.end(), bucket.begin(), bucket.begin() + static_cast<std::ptrdiff_t>(take));
		spare.insert(spare.end(), bucket.begin() + static_cast<std::ptrdiff_t>(take), bucket.end());
	}
	// More cells than the budget (one each is the least a cell gets): the strongest winners stay.
	if (kept.size() > static_cast<size_t>(max_total)) {
		std::partial_sort(kept.begin(), kept.begin() + max_total, kept.end(), stronger);
		kept.resize(static_cast<size_t>(max_total));
		return kept;
	}
	// Cells without texture leave budget unused; give it to the strongest of the rest.
	if (kept.size() < static_cast<size_t>(max_total) && !spare.empty()) {
		const auto extra = std::min(spare.size(), static_cast<size_t>(max_total) - kept.size());
		std::partial_sort(spare.begin(), spare.begin() + static_cast<std::ptrdiff_t>(extra), spare.end(),
				  stronger);
		kept.insert(kept.end(), spare.begin(), spare.begin() + static_cast<std::ptrdiff_t>(extra));
	}
	return kept;
}

FrameFeatures extract_features(const cv::Mat &image, const FeatureParams &params, int colour_radius,
			       const cv::Mat *grey_given)
{
	if (image.empty())
		return {}; // nothing to detect (a zero-sized frame reaches here only from a broken source)
	cv::Mat grey;
	if (grey_given != nullptr)
		grey = *grey_given;
	else if (image.channels() == 3)
		cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
	else
		grey = image;

	FrameFeatures features;
	// Detect several times the budget, then bucket: the grid decides which survive, not raw response.
	const int detected_at_most = params.max_features * std::max(params.candidates_per_feature, 1);
	if (params.detector == Detector::Orb) {
		auto orb = cv::ORB::create(detected_at_most, params.orb_scale, params.orb_levels, 31, 0, 2,
					   cv::ORB::HARRIS_SCORE, 31, params.orb_fast_threshold);
		std::vector<cv::KeyPoint> detected;
		orb->detect(grey, detected);
		features.keypoints = bucket_keypoints(std::move(detected), grey.size(), params.grid_cols,
						      params.grid_rows, params.max_features);
		orb->compute(grey, features.keypoints, features.descriptors);
		features.norm_type = cv::NORM_HAMMING;
	} else {
		const cv::Mat integral = surf_integral(grey);
		SurfParams surf = params.surf;
		surf.max_features = detected_at_most;
		const std::vector<SurfKeypoint> detected = surf_detect(integral, surf);
		std::vector<cv::KeyPoint> candidates;
		candidates.reserve(detected.size());
		for (size_t i = 0; i < detected.size(); ++i) {
			cv::KeyPoint kp = detected[i].to_cv();
			kp.class_id = static_cast<int>(i); // back to the SURF keypoint after bucketing
			candidates.push_back(kp);
		}
		std::vector<SurfKeypoint> kept;
		for (const auto &kp : bucket_keypoints(std::move(candidates), grey.size(), params.grid_cols,
						       params.grid_rows, params.max_features))
			kept.push_back(detected[static_cast<size_t>(kp.class_id)]);
		features.descriptors = surf_describe(integral, kept, surf);
		for (const auto &kp : kept)
			features.keypoints.push_back(kp.to_cv());
		features.norm_type = cv::NORM_L2;
	}
	features.colours.reserve(features.keypoints.size());
	for (const auto &kp : features.keypoints)
		features.colours.push_back(sample_colour(image, kp.pt, colour_radius));
	return features;
}

} // namespace stereod::vision
