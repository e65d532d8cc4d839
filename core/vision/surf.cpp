#include "core/vision/surf.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

namespace stereod::vision {
namespace {

/// Sums over rectangles of an integral image, clamped to the image (OpenCV layout: (h+1) x (w+1)).
class Integral
{
public:
	explicit Integral(const cv::Mat &ii) : ii_(ii), rows_(ii.rows - 1), cols_(ii.cols - 1) {}

	/// Sum of the pixels in rows [row, row+height) and columns [col, col+width).
	[[nodiscard]] float box(int row, int col, int height, int width) const
	{
		const int r0 = std::clamp(row, 0, rows_), c0 = std::clamp(col, 0, cols_);
		const int r1 = std::clamp(row + height, 0, rows_), c1 = std::clamp(col + width, 0, cols_);
		const int *top = ii_.ptr<int>(r0), *bottom = ii_.ptr<int>(r1);
		return static_cast<float>(bottom[c1] - top[c1] - bottom[c0] + top[c0]);
	}
	/// Haar wavelet responses of side `size` centred at (row, col): right minus left, bottom minus top.
	[[nodiscard]] float haar_x(int row, int col, int size) const
	{
		const int h = size / 2;
		return box(row - h, col, size, h) - box(row - h, col - h, size, h);
	}
	[[nodiscard]] float haar_y(int row, int col, int size) const
	{
		const int h = size / 2;
		return box(row, col - h, h, size) - box(row - h, col - h, h, size);
	}
	[[nodiscard]] int rows() const { return rows_; }
	[[nodiscard]] int cols() const { return cols_; }

private:
	const cv::Mat &ii_;
	int rows_, cols_;
};

/// det(H) and the Laplacian's sign of one filter size, on the octave's sampling grid.
struct ResponseLayer {
	int filter = 0;
	int step = 0;
	int rows = 0, cols = 0;
	std::vector<float> det;
	std::vector<int8_t> laplacian;
	[[nodiscard]] float at(int r, int c) const { return det[static_cast<size_t>(r * cols + c)]; }
};

int filter_size(int octave, int interval)
{
	return 3 * ((1 << (octave + 1)) * (interval + 1) + 1); // 9 15 21 27 | 15 27 39 51 | 27 51 75 99 | ...
}

ResponseLayer build_layer(const Integral &integral, int filter, int step)
{
	ResponseLayer layer;
	layer.filter = filter;
	layer.step = step;
	layer.rows = integral.rows() / step;
	layer.cols = integral.cols() / step;
	layer.det.assign(static_cast<size_t>(layer.rows * layer.cols), 0.0F);
	layer.laplacian.assign(layer.det.size(), 0);
	const int l = filter / 3, b = (filter - 1) / 2;
	const float inv_area = 1.0F / static_cast<float>(filter * filter);
	const int margin = (b + 1) / step + 1; // cells whose filter would leave the image stay 0
	cv::parallel_for_(cv::Range(margin, std::max(margin, layer.rows - margin)), [&](const cv::Range &range) {
		for (int r = range.start; r < range.end; ++r) {
			const int y = r * step;
			for (int c = margin; c < layer.cols - margin; ++c) {
				const int x = c * step;
				const float dxx = (integral.box(y - l + 1, x - b, 2 * l - 1, filter) -
						   3 * integral.box(y - l + 1, x - l / 2, 2 * l - 1, l)) *
						  inv_area;
				const float dyy = (integral.box(y - b, x - l + 1, filter, 2 * l - 1) -
						   3 * integral.box(y - l / 2, x - l + 1, l, 2 * l - 1)) *
						  inv_area;
				const float dxy =
					(integral.box(y - l, x + 1, l, l) + integral.box(y + 1, x - l, l, l) -
					 integral.box(y - l, x - l, l, l) - integral.box(y + 1, x + 1, l, l)) *
					inv_area;
				const size_t i = static_cast<size_t>(r * layer.cols + c);
				layer.det[i] = dxx * dyy - 0.81F * dxy * dxy; // 0.9: the box filters' relative weight
				layer.laplacian[i] = dxx + dyy >= 0 ? 1 : -1;
			}
		}
	});
	return layer;
}

/// A strict maximum over its 26 neighbours; ties are broken by position (a neighbour earlier in layer, row,
/// column order may equal the value, a later one may not), so a plateau of two yields exactly one point.
bool is_maximum(const ResponseLayer &below, const ResponseLayer &mid, const ResponseLayer &above, int r, int c)
{
	const float v = mid.at(r, c);
	for (int dr = -1; dr <= 1; ++dr)
		for (int dc = -1; dc <= 1; ++dc) {
			if (below.at(r + dr, c + dc) > v || above.at(r + dr, c + dc) >= v)
				return false;
			if (dr == 0 && dc == 0)
				continue;
			const bool earlier = dr < 0 || (dr == 0 && dc < 0);
			const float n = mid.at(r + dr, c + dc);
			if (earlier ? n > v : n >= v)
				return false;
		}
	return true;
}

/// Quadratic fit in (x, y, scale) around a maximum; false when the peak lies more than a cell away.
bool interpolate(const ResponseLayer &b, const ResponseLayer &m, const ResponseLayer &t, int r, int c,
		 SurfKeypoint &out)
{
	const double v = m.at(r, c);
	const cv::Vec3d g((m.at(r, c + 1) - m.at(r, c - 1)) / 2.0, (m.at(r + 1, c) - m.at(r - 1, c)) / 2.0,
			  (t.at(r, c) - b.at(r, c)) / 2.0);
	const double dxx = m.at(r, c + 1) + m.at(r, c - 1) - 2 * v;
	const double dyy = m.at(r + 1, c) + m.at(r - 1, c) - 2 * v;
	const double dss = t.at(r, c) + b.at(r, c) - 2 * v;
	const double dxy = (m.at(r + 1, c + 1) - m.at(r + 1, c - 1) - m.at(r - 1, c + 1) + m.at(r - 1, c - 1)) / 4.0;
	const double dxs = (t.at(r, c + 1) - t.at(r, c - 1) - b.at(r, c + 1) + b.at(r, c - 1)) / 4.0;
	const double dys = (t.at(r + 1, c) - t.at(r - 1, c) - b.at(r + 1, c) + b.at(r - 1, c)) / 4.0;
	const cv::Matx33d h(dxx, dxy, dxs, dxy, dyy, dys, dxs, dys, dss);
	cv::Vec3d offset;
	if (!cv::solve(h, -g, offset, cv::DECOMP_LU))
		return false;
	// Within one cell of the sampled maximum (as OpenCV's SURF): with a sampling step of 2 or more a true peak
	// half-way between samples is common, and rejecting it would lose the point altogether.
	if (std::abs(offset[0]) > 1.0 || std::abs(offset[1]) > 1.0 || std::abs(offset[2]) > 1.0)
		return false;
	const double filter_step = m.filter - b.filter;
	out.pt =
		cv::Point2f(static_cast<float>((c + offset[0]) * m.step), static_cast<float>((r + offset[1]) * m.step));
	out.scale = static_cast<float>(1.2 / 9.0 * (m.filter + offset[2] * filter_step));
	out.response = static_cast<float>(v + 0.5 * g.dot(offset));
	out.laplacian = m.laplacian[static_cast<size_t>(r * m.cols + c)];
	return true;
}

/// Gaussian weights of the orientation samples (sigma 2s on the 13x13 grid) and of the descriptor samples
/// (sigma 3.3s on the 20x20 grid): fixed in units of s, so computed once.
struct SurfWeights {
	std::array<float, 13 * 13> orientation{};
	std::array<float, 20 * 20> descriptor{};
	SurfWeights()
	{
		for (int i = -6; i <= 6; ++i)
			for (int j = -6; j <= 6; ++j)
				orientation[static_cast<size_t>((i + 6) * 13 + (j + 6))] =
					std::exp(-static_cast<float>(i * i + j * j) / (2.0F * 2.0F * 2.0F));
		for (int i = -10; i < 10; ++i)
			for (int j = -10; j < 10; ++j) {
				const float u = static_cast<float>(i) + 0.5F, v = static_cast<float>(j) + 0.5F;
				descriptor[static_cast<size_t>((i + 10) * 20 + (j + 10))] =
					std::exp(-(u * u + v * v) / (2.0F * 3.3F * 3.3F));
			}
	}
};

const SurfWeights &weights()
{
	static const SurfWeights w;
	return w;
}

float orientation(const Integral &integral, const SurfKeypoint &kp)
{
	const int s = std::max(1, static_cast<int>(std::lround(kp.scale)));
	const int row = static_cast<int>(std::lround(kp.pt.y)), col = static_cast<int>(std::lround(kp.pt.x));
	struct Sample {
		float angle, dx, dy;
	};
	std::array<Sample, 113> samples{};
	size_t n = 0;
	for (int i = -6; i <= 6; ++i)
		for (int j = -6; j <= 6; ++j) {
			if (i * i + j * j >= 36)
				continue;
			const float w = weights().orientation[static_cast<size_t>((i + 6) * 13 + (j + 6))];
			const float dx = w * integral.haar_x(row + j * s, col + i * s, 4 * s);
			const float dy = w * integral.haar_y(row + j * s, col + i * s, 4 * s);
			samples[n++] = {std::atan2(dy, dx), dx, dy};
		}
	// A window of pi/3 swept around the circle: with the samples sorted by angle, each window is a run of
	// consecutive samples (wrapping), so the sums update as the window's ends move.
	std::sort(samples.begin(), samples.begin() + static_cast<std::ptrdiff_t>(n),
		  [](const Sample &a, const Sample &b) { return a.angle < b.angle; });
	constexpr float kPi = std::numbers::pi_v<float>, kWindow = kPi / 3;
	float best = -1, best_angle = 0, sx = 0, sy = 0;
	size_t end = 0; // samples [start, end) (indices modulo n, angles unwrapped) are in the window
	auto angle_at = [&](size_t k) { return samples[k % n].angle + (k >= n ? 2 * kPi : 0.0F); };
	for (size_t start = 0; start < n; ++start) {
		if (end < start)
			end = start;
		while (end < start + n && angle_at(end) < samples[start].angle + kWindow) {
			sx += samples[end % n].dx;
			sy += samples[end % n].dy;
			++end;
		}
		const float magnitude = sx * sx + sy * sy;
		if (magnitude > best) {
			best = magnitude;
			best_angle = std::atan2(sy, sx);
		}
		sx -= samples[start].dx; // the window moves past this sample
		sy -= samples[start].dy;
	}
	return best_angle;
}

/// Adds `share` of one rotated Haar sample (du, dv) to subregion `cell`: sum du, sum dv, sum |du|, sum |dv|
/// (64-d), or the extended 128-d split of du by the sign of dv and of dv by the sign of du.
void add_to_cell(float *out, int cell, float du, float dv, float share, bool extended)
{
	const float su = share * du, sv = share * dv;
	if (!extended) {
		float *d = out + cell * 4;
		d[0] += su;
		d[1] += sv;
		d[2] += std::abs(su);
		d[3] += std::abs(sv);
		return;
	}
	float *d = out + cell * 8;
	float *u_half = dv >= 0 ? d : d + 2;
	float *v_half = du >= 0 ? d + 4 : d + 6;
	u_half[0] += su;
	u_half[1] += std::abs(su);
	v_half[0] += sv;
	v_half[1] += std::abs(sv);
}

void describe(const Integral &integral, const SurfKeypoint &kp, bool extended, float *out)
{
	const int size = extended ? 128 : 64;
	std::fill(out, out + size, 0.0F);
	const float s = kp.scale;
	const int haar = std::max(2, 2 * static_cast<int>(std::lround(s)));
	const float co = std::cos(kp.orientation), si = std::sin(kp.orientation);
	for (int i = -10; i < 10; ++i) {
		for (int j = -10; j < 10; ++j) {
			const float u = static_cast<float>(i) + 0.5F, v = static_cast<float>(j) + 0.5F;
			const int px = static_cast<int>(std::lround(kp.pt.x + s * (co * u - si * v)));
			const int py = static_cast<int>(std::lround(kp.pt.y + s * (si * u + co * v)));
			const float w = weights().descriptor[static_cast<size_t>((i + 10) * 20 + (j + 10))];
			const float dx = integral.haar_x(py, px, haar), dy = integral.haar_y(py, px, haar);
			const float du = w * (dx * co + dy * si);
			const float dv = w * (-dx * si + dy * co);
			// Soft binning: a sample near a subregion's edge shares itself with the neighbour, bilinearly,
			// so a small rotation or shift moves weight between cells gradually instead of all at once.
			const float cu = (static_cast<float>(i + 10) + 0.5F) / 5.0F - 0.5F;
			const float cv_ = (static_cast<float>(j + 10) + 0.5F) / 5.0F - 0.5F;
			const int cu0 = static_cast<int>(std::floor(cu)), cv0 = static_cast<int>(std::floor(cv_));
			const float fu = cu - static_cast<float>(cu0), fv = cv_ - static_cast<float>(cv0);
			for (int bv = 0; bv < 2; ++bv) {
				const int cy = cv0 + bv;
				if (cy < 0 || cy > 3)
					continue;
				for (int bu = 0; bu < 2; ++bu) {
					const int cx = cu0 + bu;
					if (cx < 0 || cx > 3)
						continue;
					const float share = (bu != 0 ? fu : 1 - fu) * (bv != 0 ? fv : 1 - fv);
					add_to_cell(out, cy * 4 + cx, du, dv, share, extended);
				}
			}
		}
	}
	float norm = 0;
	for (int k = 0; k < size; ++k)
		norm += out[k] * out[k];
	norm = std::sqrt(norm);
	if (norm > 0)
		for (int k = 0; k < size; ++k)
			out[k] /= norm;
}

} // namespace

cv::KeyPoint SurfKeypoint::to_cv() const
{
	// OpenCV's convention: size is the diameter of the described region's scale, 9 px per 1.2 sigma.
	return cv::KeyPoint(pt, scale * 9.0F / 1.2F, orientation * 180.0F / std::numbers::pi_v<float>, response, 0,
			    laplacian);
}

cv::Mat surf_integral(const cv::Mat &grey)
{
	CV_Assert(grey.type() == CV_8UC1);
	CV_Assert(static_cast<double>(grey.total()) * 255.0 < 2147483647.0); // int sums cannot overflow
	cv::Mat ii;
	cv::integral(grey, ii, CV_32S);
	return ii;
}

std::vector<SurfKeypoint> surf_detect(const cv::Mat &ii, const SurfParams &params)
{
	const Integral integral(ii);
	std::vector<SurfKeypoint> keypoints;
	for (int o = 0; o < params.octaves; ++o) {
		const int step = params.initial_step << o;
		if (filter_size(o, 3) > std::min(integral.rows(), integral.cols()))
			break;
		std::array<ResponseLayer, 4> layers;
		for (int i = 0; i < 4; ++i)
			layers[static_cast<size_t>(i)] = build_layer(integral, filter_size(o, i), step);
		for (int i = 1; i <= 2; ++i) {
			const ResponseLayer &b = layers[static_cast<size_t>(i - 1)],
					    &m = layers[static_cast<size_t>(i)],
					    &t = layers[static_cast<size_t>(i + 1)];
			const int margin = ((t.filter - 1) / 2 + 1) / step + 2;
			for (int r = margin; r < m.rows - margin; ++r)
				for (int c = margin; c < m.cols - margin; ++c) {
					if (m.at(r, c) < params.hessian_threshold || !is_maximum(b, m, t, r, c))
						continue;
					SurfKeypoint kp;
					if (interpolate(b, m, t, r, c, kp))
						keypoints.push_back(kp);
				}
		}
	}
	if (params.max_features > 0 && keypoints.size() > static_cast<size_t>(params.max_features)) {
		std::nth_element(keypoints.begin(), keypoints.begin() + params.max_features, keypoints.end(),
				 [](const SurfKeypoint &a, const SurfKeypoint &b) { return a.response > b.response; });
		keypoints.resize(static_cast<size_t>(params.max_features));
	}
	return keypoints;
}

cv::Mat surf_describe(const cv::Mat &ii, std::vector<SurfKeypoint> &keypoints, const SurfParams &params)
{
	const Integral integral(ii);
	const int size = params.extended ? 128 : 64;
	cv::Mat descriptors(static_cast<int>(keypoints.size()), size, CV_32F);
	cv::parallel_for_(cv::Range(0, static_cast<int>(keypoints.size())), [&](const cv::Range &range) {
		for (int k = range.start; k < range.end; ++k) {
			SurfKeypoint &kp = keypoints[static_cast<size_t>(k)];
			kp.orientation = params.upright ? 0.0F : orientation(integral, kp);
			describe(integral, kp, params.extended, descriptors.ptr<float>(k));
		}
	});
	return descriptors;
}

} // namespace stereod::vision
