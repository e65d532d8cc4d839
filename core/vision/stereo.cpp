#include "core/vision/stereo.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace stereod::vision {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/// Sum of absolute differences between the left window at (lx, ly) and the right window at (rx, ry);
/// the caller has checked that both windows lie inside their images.
int window_sad(const cv::Mat &left, const cv::Mat &right, int lx, int ly, int rx, int ry, int r)
{
	int sad = 0;
	for (int dy = -r; dy <= r; ++dy) {
		const uint8_t *a = left.ptr<uint8_t>(ly + dy) + lx - r;
		const uint8_t *b = right.ptr<uint8_t>(ry + dy) + rx - r;
		for (int dx = 0; dx <= 2 * r; ++dx)
			sad += std::abs(static_cast<int>(a[dx]) - static_cast<int>(b[dx]));
	}
	return sad;
}

bool window_inside(const cv::Mat &image, int x, int y, int r)
{
	return x - r >= 0 && y - r >= 0 && x + r < image.cols && y + r < image.rows;
}

/// Sub-pixel offset of the minimum of costs (-1, a), (0, b), (1, c) with b the smallest: the vertex of two
/// lines of equal and opposite slope (equiangular fit). SAD costs are V-shaped near the minimum, and a
/// parabola through them pulls the estimate towards whole pixels (about 0.13 px at 12.8 px in the tests).
double vertex_offset(double a, double b, double c)
{
	const double rise = std::max(a, c) - b;
	if (!(rise > 0))
		return 0;
	return std::clamp(0.5 * (a - c) / rise, -0.5, 0.5);
}

int descriptor_distance(const cv::Mat &a, int i, const cv::Mat &b, int j, int norm_type)
{
	const double d = cv::norm(a.row(i), b.row(j), norm_type);
	// L2 descriptors (SURF) are unit vectors: scale to the same 0..~256 range as Hamming bits.
	return norm_type == cv::NORM_HAMMING ? static_cast<int>(d) : static_cast<int>(d * 256);
}

/// Right keypoint indices sorted by row, for band lookups.
struct RowIndex {
	std::vector<int> order;
	std::vector<float> rows;
	explicit RowIndex(const std::vector<cv::KeyPoint> &keypoints)
	{
		order.resize(keypoints.size());
		std::iota(order.begin(), order.end(), 0);
		std::sort(order.begin(), order.end(), [&](int a, int b) {
			return keypoints[static_cast<size_t>(a)].pt.y < keypoints[static_cast<size_t>(b)].pt.y;
		});
		rows.reserve(order.size());
		for (int i : order)
			rows.push_back(keypoints[static_cast<size_t>(i)].pt.y);
	}
	/// [first, last) positions in `order` with rows in [lo, hi].
	[[nodiscard]] std::pair<size_t, size_t> band(float lo, float hi) const
	{
		const auto first = std::lower_bound(rows.begin(), rows.end(), lo);
		const auto last = std::upper_bound(first, rows.end(), hi);
		return {static_cast<size_t>(first - rows.begin()), static_cast<size_t>(last - rows.begin())};
	}
};

struct Best {
	int index = -1;
	int distance = std::numeric_limits<int>::max();
	int second = std::numeric_limits<int>::max();
	void offer(int candidate, int d)
	{
		if (d < distance) {
			second = distance;
			distance = d;
			index = candidate;
		} else if (d < second) {
			second = d;
		}
	}
};

} // namespace

void CalibrationHealth::add(const StereoSummary &frame)
{
	if (frame.matched < 10 || !std::isfinite(frame.median_row_diff_px))
		return; // too few matches to say anything about the rig
	++frames_;
	const double weight = 1.0 / static_cast<double>(std::min<uint64_t>(frames_, static_cast<uint64_t>(window_)));
	const double outside = frame.candidates > 0 ? static_cast<double>(frame.outside_band) / frame.candidates : 0;
	row_diff_px_ += weight * (frame.median_row_diff_px - row_diff_px_);
	outside_ += weight * (outside - outside_);
}

float median_of(std::vector<float> values)
{
	std::erase_if(values, [](float v) { return !std::isfinite(v); });
	if (values.empty())
		return kNaN;
	const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
	std::nth_element(values.begin(), mid, values.end());
	return *mid;
}

float refine_disparity(const cv::Mat &left_grey, const cv::Mat &right_grey, cv::Point2f left_pt, float disparity_px,
		       int radius, int window_radius)
{
	const int x = static_cast<int>(std::lround(left_pt.x));
	const int y = static_cast<int>(std::lround(left_pt.y));
	const int d0 = static_cast<int>(std::lround(disparity_px));
	if (!window_inside(left_grey, x, y, window_radius))
		return kNaN;
	// One extra disparity on each side, so the fit has both neighbours of an edge minimum.
	const int lo = d0 - radius - 1, hi = d0 + radius + 1;
	if (!window_inside(right_grey, x - hi, y, window_radius) ||
	    !window_inside(right_grey, x - lo, y, window_radius))
		return kNaN;
	std::array<int, 64> cost{};
	if (hi - lo + 1 > static_cast<int>(cost.size()))
		return kNaN;
	int best = -1;
	for (int d = lo; d <= hi; ++d) {
		cost[static_cast<size_t>(d - lo)] = window_sad(left_grey, right_grey, x, y, x - d, y, window_radius);
		if (d > lo && d < hi &&
		    (best < 0 || cost[static_cast<size_t>(d - lo)] < cost[static_cast<size_t>(best - lo)]))
			best = d;
	}
	const auto at = [&](int d) { return static_cast<double>(cost[static_cast<size_t>(d - lo)]); };
	// A minimum on the edge of the searched range is not a minimum: the descriptor match was off.
	if (best == lo + 1 && at(lo) <= at(best))
		return kNaN;
	if (best == hi - 1 && at(hi) <= at(best))
		return kNaN;
	// The refined disparity belongs to the integer pixel; carry it to the keypoint's own column, which is
	// the same disparity on a surface seen front-on and within the noise otherwise.
	return static_cast<float>(best + vertex_offset(at(best - 1), at(best), at(best + 1)));
}

float row_offset(const cv::Mat &left_grey, const cv::Mat &right_grey, cv::Point2f left_pt, float disparity_px,
		 int window_radius)
{
	const int x = static_cast<int>(std::lround(left_pt.x));
	const int y = static_cast<int>(std::lround(left_pt.y));
	const int rx = x - static_cast<int>(std::lround(disparity_px));
	constexpr int kReach = 2;
	if (!window_inside(left_grey, x, y, window_radius) ||
	    !window_inside(right_grey, rx, y - kReach - 1, window_radius) ||
	    !window_inside(right_grey, rx, y + kReach + 1, window_radius))
		return kNaN;
	std::array<double, 2 * kReach + 3> cost{};
	for (int dy = -kReach - 1; dy <= kReach + 1; ++dy)
		cost[static_cast<size_t>(dy + kReach + 1)] =
			window_sad(left_grey, right_grey, x, y, rx, y + dy, window_radius);
	size_t best = 1;
	for (size_t k = 2; k + 1 < cost.size(); ++k)
		if (cost[k] < cost[best])
			best = k;
	const double dy =
		static_cast<double>(best) - kReach - 1 + vertex_offset(cost[best - 1], cost[best], cost[best + 1]);
	return static_cast<float>(-dy);
}

StereoDepth match_stereo(const FrameFeatures &left, const FrameFeatures &right, const cv::Mat &left_grey,
			 const cv::Mat &right_grey, const geometry::StereoRig &rig, const StereoParams &params,
			 double detector_scale_step)
{
	const size_t n_left = left.keypoints.size();
	StereoDepth out;
	out.disparity.assign(n_left, kNaN);
	out.xyz.assign(n_left, cv::Vec3f(kNaN, kNaN, kNaN));
	out.right_index.assign(n_left, -1);
	if (n_left == 0 || right.keypoints.empty() || left.descriptors.empty() || right.descriptors.empty() ||
	    left.norm_type != right.norm_type)
		return out;

	const double step = detector_scale_step > 1 ? detector_scale_step : 1.2;
	const double max_size_ratio = params.max_size_ratio > 0 ? params.max_size_ratio : step * 1.05;
	// Keypoints found on pyramid level L are located to about step^L pixels; the row tolerance is one pixel
	// of that level, so a coarse-level corner is not refused for its coarse position.
	const auto row_tolerance = [&](const cv::KeyPoint &kp) {
		return static_cast<float>(params.max_row_diff_px * std::pow(step, std::max(kp.octave, 0)));
	};
	const auto compatible = [&](const cv::KeyPoint &l, const cv::KeyPoint &r) {
		const double d = l.pt.x - r.pt.x;
		if (d < params.min_disparity_px || d > params.max_disparity_px)
			return false;
		const double ratio = l.size > r.size ? l.size / r.size : r.size / l.size;
		return ratio <= max_size_ratio;
	};

	const RowIndex right_rows(right.keypoints);
	const float health_band = static_cast<float>(std::max(params.health_band_px, params.max_row_diff_px));

	// Left -> right: the best candidate in the epipolar band, and (for health) in the wide band.
	std::vector<Best> forward(n_left);
	for (size_t i = 0; i < n_left; ++i) {
		const cv::KeyPoint &l = left.keypoints[i];
		const float tolerance = row_tolerance(l);
		const auto [first, last] = right_rows.band(l.pt.y - std::max(tolerance, health_band),
							   l.pt.y + std::max(tolerance, health_band));
		Best wide;
		for (size_t k = first; k < last; ++k) {
			const int j = right_rows.order[k];
			const cv::KeyPoint &r = right.keypoints[static_cast<size_t>(j)];
			if (!compatible(l, r))
				continue;
			const int d = descriptor_distance(left.descriptors, static_cast<int>(i), right.descriptors, j,
							  left.norm_type);
			wide.offer(j, d);
			if (std::abs(l.pt.y - r.pt.y) <= tolerance)
				forward[i].offer(j, d);
		}
		if (wide.index >= 0 && wide.distance <= params.max_distance) {
			++out.candidates;
			if (std::abs(l.pt.y - right.keypoints[static_cast<size_t>(wide.index)].pt.y) > row_tolerance(l))
				++out.outside_band;
		}
	}

	// Right -> left, for the two-way check: the best left keypoint in the band for each right keypoint that
	// some left keypoint chose.
	const RowIndex left_rows(left.keypoints);
	std::vector<int> backward(right.keypoints.size(), -2); // -2: not asked
	for (size_t i = 0; i < n_left; ++i) {
		const Best &f = forward[i];
		if (f.index < 0 || f.distance > params.max_distance)
			continue;
		if (f.second != std::numeric_limits<int>::max() &&
		    static_cast<float>(f.distance) >= params.ratio * static_cast<float>(f.second))
			continue;
		int &back = backward[static_cast<size_t>(f.index)];
		if (back == -2) {
			const cv::KeyPoint &r = right.keypoints[static_cast<size_t>(f.index)];
			// The widest tolerance any level allows; each candidate is then held to its own.
			const float reach = row_tolerance(cv::KeyPoint(r.pt, r.size, -1, 0, 16));
			const auto [first, last] = left_rows.band(r.pt.y - reach, r.pt.y + reach);
			Best b;
			for (size_t k = first; k < last; ++k) {
				const int li = left_rows.order[k];
				const cv::KeyPoint &l = left.keypoints[static_cast<size_t>(li)];
				if (!compatible(l, r) || std::abs(l.pt.y - r.pt.y) > row_tolerance(l))
					continue;
				b.offer(li, descriptor_distance(left.descriptors, li, right.descriptors, f.index,
								left.norm_type));
			}
			back = b.index;
		}
		if (back != static_cast<int>(i))
			continue;

		const cv::KeyPoint &l = left.keypoints[i];
		const cv::KeyPoint &r = right.keypoints[static_cast<size_t>(f.index)];
		const float d = refine_disparity(left_grey, right_grey, l.pt, l.pt.x - r.pt.x, params.refine_radius_px,
						 params.window_radius_px);
		if (!(d >= static_cast<float>(params.min_disparity_px)) ||
		    d > static_cast<float>(params.max_disparity_px))
			continue;
		const auto p = rig.triangulate(l.pt.x, l.pt.y, d);
		if (!p)
			continue;
		out.disparity[i] = d;
		out.xyz[i] = cv::Vec3f(static_cast<float>((*p)[0]), static_cast<float>((*p)[1]),
				       static_cast<float>((*p)[2]));
		out.right_index[i] = f.index;
		out.row_differences.push_back(row_offset(left_grey, right_grey, l.pt, d, params.window_radius_px));
		++out.matched;
	}
	return out;
}

} // namespace stereod::vision
