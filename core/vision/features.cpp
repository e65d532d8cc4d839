#include "core/vision/features.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <functional>
#include <limits>
#include <optional>
#include <tuple>

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

namespace {

/// The cell of a grid_cols x grid_rows grid over an image of `image_size` that `pt` falls in, row-major; points
/// outside the image count in the nearest cell.
size_t grid_cell(cv::Point2f pt, cv::Size image_size, int grid_cols, int grid_rows)
{
	const int col = std::clamp(
		static_cast<int>(pt.x * static_cast<float>(grid_cols) / static_cast<float>(image_size.width)), 0,
		grid_cols - 1);
	const int row = std::clamp(
		static_cast<int>(pt.y * static_cast<float>(grid_rows) / static_cast<float>(image_size.height)), 0,
		grid_rows - 1);
	return static_cast<size_t>(row * grid_cols + col);
}

} // namespace

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
	for (const auto &kp : keypoints)
		buckets[grid_cell(kp.pt, image_size, grid_cols, grid_rows)].push_back(kp);
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

namespace {

/// OpenCV's ORB as extract_features creates it: edge threshold and patch size 31, Harris block 7, k 0.04.
constexpr int orb_edge = 31;
constexpr int orb_half_patch = 15;
constexpr int harris_block = 7;
constexpr double harris_k = 0.04;

/// The Harris corner response at `at` of an 8-bit image, Sobel gradients summed over a 7 x 7 block, scaled as
/// OpenCV's ORB scales it so the scores of candidates from different pyramid levels compare as they did.
float harris_response(const cv::Mat &image, cv::Point at)
{
	const int r = harris_block / 2;
	int64_t xx = 0, yy = 0, xy = 0;
	for (int y = at.y - r; y <= at.y + r; ++y) {
		const uint8_t *above = image.ptr<uint8_t>(y - 1);
		const uint8_t *row = image.ptr<uint8_t>(y);
		const uint8_t *below = image.ptr<uint8_t>(y + 1);
		for (int x = at.x - r; x <= at.x + r; ++x) {
			const int dx = (above[x + 1] - above[x - 1]) + 2 * (row[x + 1] - row[x - 1]) +
				       (below[x + 1] - below[x - 1]);
			const int dy = (below[x - 1] + 2 * below[x] + below[x + 1]) -
				       (above[x - 1] + 2 * above[x] + above[x + 1]);
			xx += dx * dx;
			yy += dy * dy;
			xy += dx * dy;
		}
	}
	const double scale = 1.0 / (4.0 * harris_block * 255.0);
	const double scale4 = scale * scale * scale * scale;
	const auto a = static_cast<double>(xx), b = static_cast<double>(yy), c = static_cast<double>(xy);
	return static_cast<float>((a * b - c * c - harris_k * (a + b) * (a + b)) * scale4);
}

/// The half-width, row by row, of the disc of radius 15 that ORB's orientation is measured on: it holds (u, v)
/// where u^2 + v^2 <= r (r + 1), symmetric in u and v, so the angle turns with the image.
constexpr std::array<int, orb_half_patch + 1> disc_half_widths()
{
	std::array<int, orb_half_patch + 1> half_width{};
	for (int v = 0; v <= orb_half_patch; ++v) {
		int w = 0;
		while ((w + 1) * (w + 1) + v * v <= orb_half_patch * (orb_half_patch + 1))
			++w;
		half_width[static_cast<size_t>(v)] = w;
	}
	return half_width;
}

constexpr std::array<int, orb_half_patch + 1> disc_half_width = disc_half_widths();

/// ORB's orientation: the angle (degrees) from `at` to the intensity centroid of the disc around it.
float centroid_angle(const cv::Mat &image, cv::Point at)
{
	// 32 bits hold both sums (at most 255 x 15 x 709 pixels) and let the compiler vectorise the rows.
	int32_t m10 = 0, m01 = 0;
	for (int v = -orb_half_patch; v <= orb_half_patch; ++v) {
		const uint8_t *row = image.ptr<uint8_t>(at.y + v);
		const int w = disc_half_width[static_cast<size_t>(std::abs(v))];
		int32_t row_sum = 0, row_moment = 0;
		for (int u = -w; u <= w; ++u) {
			row_sum += row[at.x + u];
			row_moment += u * row[at.x + u];
		}
		m10 += row_moment;
		m01 += v * row_sum;
	}
	return cv::fastAtan2(static_cast<float>(m01), static_cast<float>(m10));
}

} // namespace

std::vector<cv::KeyPoint> detect_orb_per_cell(const cv::Mat &grey, const FeatureParams &params)
{
	if (grey.empty() || params.max_features <= 0)
		return {};
	CV_Assert(grey.type() == CV_8UC1);
	const int grid_cols = std::max(params.grid_cols, 1);
	const int grid_rows = std::max(params.grid_rows, 1);
	const int cells = grid_cols * grid_rows;
	const int kept_per_cell = std::max(params.max_features / cells, 1) * std::max(params.candidates_per_feature, 1);

	// The pyramid as cv::ORB builds it (each level resized from the one before), so the octave and position
	// of a keypoint mean the same to cv::ORB::compute.
	const int levels = std::max(params.orb_levels, 1);
	std::vector<cv::Mat> pyramid(static_cast<size_t>(levels));
	std::vector<float> level_scale(static_cast<size_t>(levels));
	pyramid[0] = grey;
	level_scale[0] = 1.0F;
	for (size_t level = 1; level < pyramid.size(); ++level) {
		level_scale[level] = level_scale[level - 1] * params.orb_scale;
		const cv::Size size(cvRound(static_cast<float>(grey.cols) / level_scale[level]),
				    cvRound(static_cast<float>(grey.rows) / level_scale[level]));
		if (size.width <= 2 * orb_edge || size.height <= 2 * orb_edge) {
			pyramid.resize(level);
			break;
		}
		cv::resize(pyramid[level - 1], pyramid[level], size, 0, 0, cv::INTER_LINEAR);
	}

	// Each cell keeps its strongest corners by FAST score, from every level at once. FAST costs in proportion
	// to the corners it finds (aloe at threshold 12: 58 000 over four levels, 10 ms), and a textured cell
	// keeps only its strongest few, so FAST runs first at a high threshold; a cell holding fewer than its
	// share of such corners runs again at the configured threshold over its own region. FAST's corners at a
	// threshold are exactly those at a lower one scoring at least that much (its score does not depend on
	// the threshold, and non-maximum suppression only drops a corner for a stronger neighbour, which the
	// higher threshold finds too), so the candidates are the same as from one pass at the configured
	// threshold (Features.TheFirstPassAtAHighThresholdFindsTheSameCandidates).
	const int low_threshold = params.orb_fast_threshold;
	const int high_threshold = std::max(low_threshold, params.orb_fast_first_pass_threshold);
	std::vector<std::vector<cv::KeyPoint>> buckets(static_cast<size_t>(cells));
	std::vector<cv::KeyPoint> corners;
	// Files the corners of one level found in `region` (level pixels) into their cells; with `only_cell` set,
	// only those of that cell.
	const auto file_corners = [&](size_t level, cv::Rect region, std::optional<size_t> only_cell) {
		const cv::Mat &image = pyramid[level];
		for (cv::KeyPoint corner : corners) {
			corner.pt.x += static_cast<float>(region.x);
			corner.pt.y += static_cast<float>(region.y);
			// As cv::ORB: nothing within the edge threshold of the level's border (the descriptor's patch).
			if (corner.pt.x < orb_edge || corner.pt.y < orb_edge ||
			    corner.pt.x >= static_cast<float>(image.cols - orb_edge) ||
			    corner.pt.y >= static_cast<float>(image.rows - orb_edge))
				continue;
			corner.octave = static_cast<int>(level);
			corner.pt *= level_scale[level];
			corner.size = static_cast<float>(orb_edge) * level_scale[level];
			const size_t cell = grid_cell(corner.pt, grey.size(), grid_cols, grid_rows);
			if (!only_cell || *only_cell == cell)
				buckets[cell].push_back(corner);
		}
	};
	for (size_t level = 0; level < pyramid.size(); ++level) {
		corners.clear();
		cv::FAST(pyramid[level], corners, high_threshold, true);
		file_corners(level, cv::Rect(0, 0, pyramid[level].cols, pyramid[level].rows), std::nullopt);
	}
	if (high_threshold > low_threshold) {
		for (size_t cell = 0; cell < buckets.size(); ++cell) {
			if (buckets[cell].size() >= static_cast<size_t>(kept_per_cell))
				continue;
			buckets[cell].clear();
			const auto col = static_cast<int>(cell) % grid_cols;
			const auto row = static_cast<int>(cell) / grid_cols;
			const float x0 = static_cast<float>(col * grey.cols) / static_cast<float>(grid_cols);
			const float x1 = static_cast<float>((col + 1) * grey.cols) / static_cast<float>(grid_cols);
			const float y0 = static_cast<float>(row * grey.rows) / static_cast<float>(grid_rows);
			const float y1 = static_cast<float>((row + 1) * grey.rows) / static_cast<float>(grid_rows);
			for (size_t level = 0; level < pyramid.size(); ++level) {
				const cv::Mat &image = pyramid[level];
				const float s = level_scale[level];
				// FAST tests a circle of radius 3 and compares each corner with its 8 neighbours, so
				// the region reaches 5 pixels past the cell: every pixel of it, and its neighbours, are
				// tested as in the whole level.
				constexpr int margin = 5;
				const cv::Rect region =
					cv::Rect(cv::Point(static_cast<int>(std::floor(x0 / s)) - margin,
							   static_cast<int>(std::floor(y0 / s)) - margin),
						 cv::Point(static_cast<int>(std::ceil(x1 / s)) + margin,
							   static_cast<int>(std::ceil(y1 / s)) + margin)) &
					cv::Rect(0, 0, image.cols, image.rows);
				if (region.empty())
					continue;
				corners.clear();
				cv::FAST(image(region), corners, low_threshold, true);
				file_corners(level, region, cell);
			}
		}
	}
	// Ties in FAST's integer scores are common: a total order makes the kept corners the same whatever order
	// the passes found them in.
	const auto stronger = [](const cv::KeyPoint &a, const cv::KeyPoint &b) {
		return std::tie(b.response, a.octave, a.pt.y, a.pt.x) < std::tie(a.response, b.octave, b.pt.y, b.pt.x);
	};
	std::vector<cv::KeyPoint> candidates;
	candidates.reserve(static_cast<size_t>(kept_per_cell) * buckets.size());
	for (auto &bucket : buckets) {
		if (bucket.size() > static_cast<size_t>(kept_per_cell)) {
			std::nth_element(bucket.begin(), bucket.begin() + kept_per_cell, bucket.end(), stronger);
			bucket.resize(static_cast<size_t>(kept_per_cell));
		}
		for (cv::KeyPoint &candidate : bucket) {
			const float s = level_scale[static_cast<size_t>(candidate.octave)];
			const cv::Point at(cvRound(candidate.pt.x / s), cvRound(candidate.pt.y / s));
			candidate.response = harris_response(pyramid[static_cast<size_t>(candidate.octave)], at);
			candidates.push_back(candidate);
		}
	}
	// Corners far weaker than the image's best are the sensor's noise on a plain surface, not structure
	// (goodFeaturesToTrack's quality level): they would take a cell's share from nothing.
	if (params.min_corner_quality > 0.0F && !candidates.empty()) {
		// The frame's best, as the 99th percentile: one outstanding corner (a lamp's edge against the sky) must
		// not set the floor for every other.
		std::vector<float> responses(candidates.size());
		std::transform(candidates.begin(), candidates.end(), responses.begin(),
			       [](const cv::KeyPoint &c) { return c.response; });
		const auto rank = static_cast<std::ptrdiff_t>(responses.size() / 100);
		std::nth_element(responses.begin(), responses.begin() + rank, responses.end(), std::greater<>());
		const float best = responses[static_cast<size_t>(rank)];
		const float floor = best * params.min_corner_quality;
		std::erase_if(candidates, [floor](const cv::KeyPoint &c) { return c.response < floor; });
	}
	std::vector<cv::KeyPoint> kept =
		bucket_keypoints(std::move(candidates), grey.size(), grid_cols, grid_rows, params.max_features);

	for (cv::KeyPoint &kp : kept) {
		const float s = level_scale[static_cast<size_t>(kp.octave)];
		const cv::Point at(cvRound(kp.pt.x / s), cvRound(kp.pt.y / s));
		kp.angle = centroid_angle(pyramid[static_cast<size_t>(kp.octave)], at);
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
		auto orb = cv::ORB::create(detected_at_most, params.orb_scale, params.orb_levels, orb_edge, 0, 2,
					   cv::ORB::HARRIS_SCORE, orb_edge, params.orb_fast_threshold);
		if (params.candidate_selection == CandidateSelection::PerCell && grey.type() == CV_8UC1) {
			features.keypoints = detect_orb_per_cell(grey, params);
		} else {
			std::vector<cv::KeyPoint> detected;
			orb->detect(grey, detected);
			features.keypoints = bucket_keypoints(std::move(detected), grey.size(), params.grid_cols,
							      params.grid_rows, params.max_features);
		}
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
