#include "core/vision/stereo.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <optional>

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

/// Zero-mean normalised correlation of `patch` at every column of a strip of its height: the best column,
/// and the best more than 2 columns from it (a second candidate rather than the best's own slope).
struct RowPeak {
	int column = -1;
	float best = -2;
	float elsewhere = -2;
};

/// acc[k] += weight * pixels[k]: a function of its own so that the compiler knows the arrays do not overlap
/// (uint8_t may alias anything) and vectorises the loop.
void add_scaled(int32_t *__restrict acc, const uint8_t *__restrict pixels, int32_t weight, int count)
{
	for (int k = 0; k < count; ++k)
		acc[k] += weight * static_cast<int32_t>(pixels[k]);
}

/// sum[k] += pixels[k], squares[k] += pixels[k]^2.
void add_column(int32_t *__restrict sum, int32_t *__restrict squares, const uint8_t *__restrict pixels, int count)
{
	for (int k = 0; k < count; ++k) {
		const int32_t v = pixels[k];
		sum[k] += v;
		squares[k] += v * v;
	}
}

/// score[k] = (cross[k] - patch_sum sum[k] / n) / sqrt(patch_spread (squares[k] - sum[k]^2 / n)), -1 where
/// either window is flat.
void correlations(float *__restrict score, const int32_t *__restrict cross, const float *__restrict sum,
		  const float *__restrict squares, float patch_sum, float patch_spread, float inverse_n, int count)
{
	for (int k = 0; k < count; ++k) {
		const float spread = patch_spread * (squares[k] - sum[k] * sum[k] * inverse_n);
		const float numerator = static_cast<float>(cross[k]) - patch_sum * sum[k] * inverse_n;
		const float correlation = numerator / std::sqrt(std::max(spread, 1e-6F)); // no branch: vectorises
		score[k] = spread > 0 ? correlation : -1.0F;
	}
}

/// Written out rather than cv::matchTemplate, which costs about 0.15 ms a call at this size (its set-up
/// dominates): the cross term's inner loop runs along the strip and vectorises, and the windows' sums slide.
/// The numerator needs no mean of the strip's window: sum((T - mean T) R) = sum(T R) - sum(T) sum(R) / n.
RowPeak correlate_along(const cv::Mat &strip, const cv::Mat &patch, RowSearchBuffers &buffers)
{
	const int side = patch.cols;
	const int positions = strip.cols - side + 1;
	auto &cross = buffers.cross;
	auto &column_sum = buffers.column_sum;
	auto &column_squares = buffers.column_squares;
	cross.assign(static_cast<size_t>(positions), 0);
	column_sum.assign(static_cast<size_t>(strip.cols), 0);
	column_squares.assign(static_cast<size_t>(strip.cols), 0);
	int64_t patch_sum = 0, patch_squares = 0;
	for (int dy = 0; dy < side; ++dy) {
		const uint8_t *t = patch.ptr<uint8_t>(dy);
		const uint8_t *row = strip.ptr<uint8_t>(dy);
		for (int dx = 0; dx < side; ++dx) {
			const int32_t weight = t[dx];
			patch_sum += weight;
			patch_squares += weight * weight;
			add_scaled(cross.data(), row + dx, weight, positions);
		}
		add_column(column_sum.data(), column_squares.data(), row, strip.cols);
	}
	// The windows' sums slide along the strip; then every position's correlation in one loop that vectorises.
	auto &window_sum = buffers.window_sum;
	auto &window_squares = buffers.window_squares;
	window_sum.resize(static_cast<size_t>(positions));
	window_squares.resize(static_cast<size_t>(positions));
	int32_t sum = 0, squares = 0;
	for (int c = 0; c < strip.cols; ++c) {
		sum += column_sum[static_cast<size_t>(c)];
		squares += column_squares[static_cast<size_t>(c)];
		if (c >= side) {
			sum -= column_sum[static_cast<size_t>(c - side)];
			squares -= column_squares[static_cast<size_t>(c - side)];
		}
		if (c >= side - 1) {
			window_sum[static_cast<size_t>(c - side + 1)] = static_cast<float>(sum);
			window_squares[static_cast<size_t>(c - side + 1)] = static_cast<float>(squares);
		}
	}
	auto &score = buffers.score;
	score.resize(static_cast<size_t>(positions));
	const float inverse_n = 1.0F / static_cast<float>(side * side);
	const auto patch_total = static_cast<float>(patch_sum);
	correlations(score.data(), cross.data(), window_sum.data(), window_squares.data(), patch_total,
		     static_cast<float>(patch_squares) - patch_total * patch_total * inverse_n, inverse_n, positions);
	RowPeak peak;
	for (int k = 0; k < positions; ++k)
		if (score[static_cast<size_t>(k)] > peak.best) {
			peak.best = score[static_cast<size_t>(k)];
			peak.column = k;
		}
	for (int k = 0; k < positions; ++k)
		if (std::abs(k - peak.column) > 2)
			peak.elsewhere = std::max(peak.elsewhere, score[static_cast<size_t>(k)]);
	return peak;
}

} // namespace

void CalibrationHealth::add(const StereoSummary &frame)
{
	if (frame.matched < 10 || !std::isfinite(frame.median_row_diff_px))
		return; // too few matches to say anything about the rig
	if (frame.candidates > 0)
		descriptor_frames_ = true;
	else if (descriptor_frames_)
		return; // the row search alone, while descriptor matches measure the rig every few frames
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
		       int radius, int window_radius, double split_px, bool *straddles)
{
	if (straddles != nullptr)
		*straddles = false;
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
	// The whole window's costs, and its four halves' (left of the centre column, right of it, above the
	// centre row, below it) for the depth-edge test.
	enum Part { kWhole, kLeft, kRight, kTop, kBottom, kParts };
	std::array<std::array<int, 64>, kParts> cost{};
	if (hi - lo + 1 > static_cast<int>(cost[0].size()))
		return kNaN;
	const int r = window_radius;
	for (int d = lo; d <= hi; ++d) {
		std::array<int, kParts> sum{};
		for (int dy = -r; dy <= r; ++dy) {
			const uint8_t *a = left_grey.ptr<uint8_t>(y + dy) + x - r;
			const uint8_t *b = right_grey.ptr<uint8_t>(y + dy) + x - d - r;
			int row_left = 0, row_right = 0, row = 0;
			for (int dx = 0; dx <= 2 * r; ++dx) {
				const int diff = std::abs(static_cast<int>(a[dx]) - static_cast<int>(b[dx]));
				row += diff;
				row_left += dx < r ? diff : 0;
				row_right += dx > r ? diff : 0;
			}
			sum[kWhole] += row;
			sum[kLeft] += row_left;
			sum[kRight] += row_right;
			sum[kTop] += dy < 0 ? row : 0;
			sum[kBottom] += dy > 0 ? row : 0;
		}
		for (size_t part = 0; part < kParts; ++part)
			cost[part][static_cast<size_t>(d - lo)] = sum[part];
	}
	// The refined disparity of one part: the minimum over the inner disparities and the V fit through it;
	// nullopt when the minimum sits on the edge of the range.
	const auto refined = [&](Part part) -> std::optional<double> {
		const auto at = [&](int d) { return static_cast<double>(cost[part][static_cast<size_t>(d - lo)]); };
		int best = lo + 1;
		for (int d = lo + 2; d < hi; ++d)
			if (at(d) < at(best))
				best = d;
		if ((best == lo + 1 && at(lo) <= at(best)) || (best == hi - 1 && at(hi) <= at(best)))
			return std::nullopt;
		return best + vertex_offset(at(best - 1), at(best), at(best + 1));
	};
	// A minimum on the edge of the searched range is not a minimum: the descriptor match was off.
	const std::optional<double> whole = refined(kWhole);
	if (!whole)
		return kNaN;
	if (split_px > 0 && straddles != nullptr) {
		// A window across a depth edge (a mover's outline against the background) holds two disparities;
		// its halves on either side of the edge then prefer different ones, and the whole window's lies
		// between them and follows neither surface. A half too flat to prefer anything (its costs vary by
		// under 2 grey levels a pixel over the range) has no say.
		const int half_pixels = r * (2 * r + 1);
		const auto textured = [&](Part part) {
			const auto [low, high] =
				std::minmax_element(cost[part].begin(), cost[part].begin() + (hi - lo + 1));
			return *high - *low >= 2 * half_pixels;
		};
		for (const auto &[a, b] : {std::pair{kLeft, kRight}, std::pair{kTop, kBottom}}) {
			if (!textured(a) || !textured(b))
				continue;
			const std::optional<double> da = refined(a), db = refined(b);
			if (!da || !db || std::abs(*da - *db) > split_px)
				*straddles = true;
		}
	}
	// The refined disparity belongs to the integer pixel; carry it to the keypoint's own column, which is
	// the same disparity on a surface seen front-on and within the noise otherwise.
	return static_cast<float>(*whole);
}

float search_row(const cv::Mat &left_grey, const cv::Mat &right_grey, cv::Point2f left_pt, const StereoParams &params,
		 RowSearchBuffers &buffers, bool *straddles)
{
	if (straddles != nullptr)
		*straddles = false;
	const int x = static_cast<int>(std::lround(left_pt.x));
	const int y = static_cast<int>(std::lround(left_pt.y));
	const int r = params.window_radius_px;
	if (!window_inside(left_grey, x, y, r) || y + r >= right_grey.rows)
		return kNaN;
	// Disparities whose right window lies inside the right image.
	const int d_lo = std::max(static_cast<int>(std::ceil(params.min_disparity_px)), x + r - right_grey.cols + 1);
	const int d_hi = std::min(static_cast<int>(std::floor(params.max_disparity_px)), x - r);
	if (d_hi - d_lo < 2)
		return kNaN;
	const int side = 2 * r + 1;
	const cv::Mat patch = left_grey(cv::Rect(x - r, y - r, side, side));
	cv::Scalar mean, deviation;
	cv::meanStdDev(patch, mean, deviation);
	// Below a few grey levels the window is flat and its correlation is that of noise.
	constexpr double kMinDeviation = 4;
	if (deviation[0] < kMinDeviation)
		return kNaN;
	// Strip column k holds the right window centred at x - d_hi + k: disparity d_hi - k.
	const RowPeak forward =
		correlate_along(right_grey(cv::Rect(x - d_hi - r, y - r, d_hi - d_lo + side, side)), patch, buffers);
	const int last = d_hi - d_lo;
	if (forward.best < params.row_search_min_ncc || forward.column == 0 || forward.column == last ||
	    1 - forward.best > params.row_search_uniqueness * (1 - forward.elsewhere))
		return kNaN;
	const int d = d_hi - forward.column;

	// Two-way: the right window at the match, searched along the left row over the same disparities.
	const int xr = x - d;
	const int b_lo = std::max(d_lo, r - xr);
	const int b_hi = std::min(d_hi, left_grey.cols - 1 - r - xr);
	if (b_hi - b_lo < 2)
		return kNaN;
	// Strip column k holds the left window centred at xr + b_lo + k: disparity b_lo + k.
	const RowPeak back = correlate_along(left_grey(cv::Rect(xr + b_lo - r, y - r, b_hi - b_lo + side, side)),
					     right_grey(cv::Rect(xr - r, y - r, side, side)), buffers);
	if (std::abs(b_lo + back.column - d) > 1)
		return kNaN;
	return refine_disparity(left_grey, right_grey, left_pt, static_cast<float>(d), params.refine_radius_px, r,
				params.edge_split_px, straddles);
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

namespace {

/// The left-camera 3D point at `pt` for disparity `d`, when `d` is in [min_disparity_px, max_disparity_px] and
/// triangulates; nothing otherwise (NaN included).
std::optional<cv::Vec3f> point_at_disparity(cv::Point2f pt, float d, const geometry::StereoRig &rig,
					    const StereoParams &params)
{
	if (!(d >= static_cast<float>(params.min_disparity_px)) || d > static_cast<float>(params.max_disparity_px))
		return std::nullopt;
	const auto p = rig.triangulate(pt.x, pt.y, d);
	if (!p)
		return std::nullopt;
	return cv::Vec3f(static_cast<float>((*p)[0]), static_cast<float>((*p)[1]), static_cast<float>((*p)[2]));
}

} // namespace

std::optional<cv::Vec3f> clean_row_depth(const cv::Mat &left_grey, const cv::Mat &right_grey, cv::Point2f left_pt,
					 const geometry::StereoRig &rig, const StereoParams &params,
					 RowSearchBuffers &buffers)
{
	bool straddles = false;
	const float d = search_row(left_grey, right_grey, left_pt, params, buffers, &straddles);
	if (straddles)
		return std::nullopt;
	return point_at_disparity(left_pt, d, rig, params);
}

namespace {

/// Left keypoint i's disparity and 3D point into `out`, when the disparity is in range and triangulates (and,
/// with drop_edge_depth, its window does not straddle a depth edge); false otherwise (NaN included).
bool store_depth(size_t i, cv::Point2f pt, float d, bool straddles, const geometry::StereoRig &rig,
		 const StereoParams &params, StereoDepth &out)
{
	if (straddles && params.drop_edge_depth)
		return false;
	const std::optional<cv::Vec3f> point = point_at_disparity(pt, d, rig, params);
	if (!point)
		return false;
	out.disparity[i] = d;
	out.xyz[i] = *point;
	out.on_edge[i] = straddles ? 1 : 0;
	return true;
}

/// Seed 002's matching of left to right keypoints under the four constraints (match_stereo), into `out`.
void match_descriptors(const FrameFeatures &left, const FrameFeatures &right, const cv::Mat &left_grey,
		       const cv::Mat &right_grey, const geometry::StereoRig &rig, const StereoParams &params,
		       double detector_scale_step, StereoDepth &out)
{
	const size_t n_left = left.keypoints.size();
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
		bool straddles = false;
		const float d = refine_disparity(left_grey, right_grey, l.pt, l.pt.x - r.pt.x, params.refine_radius_px,
						 params.window_radius_px, params.edge_split_px, &straddles);
		if (!store_depth(i, l.pt, d, straddles, rig, params, out))
			continue;
		out.right_index[i] = f.index;
		out.row_differences.push_back(row_offset(left_grey, right_grey, l.pt, d, params.window_radius_px));
		++out.matched;
	}
}

} // namespace

StereoDepth match_stereo(const FrameFeatures &left, const FrameFeatures &right, const cv::Mat &left_grey,
			 const cv::Mat &right_grey, const geometry::StereoRig &rig, const StereoParams &params,
			 double detector_scale_step)
{
	const size_t n_left = left.keypoints.size();
	StereoDepth out;
	out.disparity.assign(n_left, kNaN);
	out.xyz.assign(n_left, cv::Vec3f(kNaN, kNaN, kNaN));
	out.right_index.assign(n_left, -1);
	out.on_edge.assign(n_left, 0);
	const bool descriptors = !right.keypoints.empty() && !left.descriptors.empty() && !right.descriptors.empty() &&
				 left.norm_type == right.norm_type;
	if (n_left > 0 && descriptors)
		match_descriptors(left, right, left_grey, right_grey, rig, params, detector_scale_step, out);
	if (!params.row_search)
		return out;
	// The rest along their rows. These matches assume the rows agree: beside descriptor matches they say
	// nothing of the rig's health and stay out of row_differences. Without right keypoints they are all
	// there is, and their row offsets still show a rig drifting by a fraction of a pixel (further off, the
	// correlation refuses the matches and `matched` falls).
	RowSearchBuffers buffers;
	for (size_t i = 0; i < n_left; ++i) {
		if (!std::isnan(out.disparity[i]))
			continue;
		const cv::Point2f pt = left.keypoints[i].pt;
		bool straddles = false;
		const float d = search_row(left_grey, right_grey, pt, params, buffers, &straddles);
		if (!store_depth(i, pt, d, straddles, rig, params, out))
			continue;
		if (!descriptors)
			out.row_differences.push_back(
				row_offset(left_grey, right_grey, pt, d, params.window_radius_px));
		++out.matched;
		++out.row_searched;
	}
	return out;
}

} // namespace stereod::vision
