#include "core/vision/dense_motion.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "core/vision/stereo.hpp"
#include "core/vision/structure_tensor.hpp"

namespace stereod::vision {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/// Per cell: the unit direction across the edges of the window at its centre in `image` (the structure
/// tensor's eigenvector of the larger eigenvalue), where the smaller eigenvalue is under `ratio` times the
/// larger; (0, 0) elsewhere.
std::vector<cv::Point2f> edge_directions(const cv::Mat &image, int cols, int rows, double to_full_x, double to_full_y,
					 int window, double ratio)
{
	std::vector<cv::Point2f> across(static_cast<size_t>(cols) * static_cast<size_t>(rows), cv::Point2f(0, 0));
	// The structure tensor's entries summed over each window: products of the gradients, box-summed (zero
	// outside the image, so a window at the border sums what lies inside it).
	cv::Mat gx, gy, xx, xy, yy;
	cv::Sobel(image, gx, CV_32F, 1, 0, 3);
	cv::Sobel(image, gy, CV_32F, 0, 1, 3);
	const cv::Size box(window, window);
	cv::boxFilter(gx.mul(gx), xx, -1, box, {-1, -1}, false, cv::BORDER_CONSTANT);
	cv::boxFilter(gx.mul(gy), xy, -1, box, {-1, -1}, false, cv::BORDER_CONSTANT);
	cv::boxFilter(gy.mul(gy), yy, -1, box, {-1, -1}, false, cv::BORDER_CONSTANT);
	const double step_x = static_cast<double>(image.cols) / cols, step_y = static_cast<double>(image.rows) / rows;
	for (int r = 0; r < rows; ++r)
		for (int c = 0; c < cols; ++c) {
			const int x = static_cast<int>((c + 0.5) * step_x), y = static_cast<int>((r + 0.5) * step_y);
			const double sxx = xx.at<float>(y, x), sxy = xy.at<float>(y, x), syy = yy.at<float>(y, x);
			const std::optional<double> angle = edge_angle(sxx, sxy, syy, ratio);
			if (!angle)
				continue;
			// In full-resolution pixels the direction is the same when both axes scale alike (they do: the
			// flow image is the left image resized by one factor); scaled per axis to stay exact otherwise.
			cv::Point2d dir(std::cos(*angle) / to_full_x, std::sin(*angle) / to_full_y);
			dir /= std::hypot(dir.x, dir.y);
			across[static_cast<size_t>(r * cols + c)] = cv::Point2f(dir);
		}
	return across;
}

} // namespace

cv::Mat dense_flow_image(const cv::Mat &grey, const DenseFlowParams &params)
{
	if (grey.empty())
		return {};
	if (params.scale >= 1.0)
		return grey.clone(); // the pool's buffer is overwritten by the next capture
	cv::Mat small;
	cv::resize(grey, small, cv::Size(), params.scale, params.scale, cv::INTER_AREA);
	return small;
}

CellFlow dense_flow(const cv::Mat &prev, const cv::Mat &cur, cv::Size full_size, const DenseFlowParams &params,
		    cv::Ptr<cv::DISOpticalFlow> &dis)
{
	CellFlow cells;
	const int step = std::max(params.step_px, 1);
	cells.cols = full_size.width / step;
	cells.rows = full_size.height / step;
	const auto count = static_cast<size_t>(cells.cols) * static_cast<size_t>(cells.rows);
	cells.flow.assign(count, cv::Point2f(0, 0));
	cells.valid.assign(count, 0);
	if (prev.empty() || cur.empty() || prev.size() != cur.size() || count == 0)
		return cells;
	const double to_full_x = static_cast<double>(full_size.width) / cur.cols;
	const double to_full_y = static_cast<double>(full_size.height) / cur.rows;
	if (params.aperture_ratio > 0)
		cells.across = edge_directions(prev, cells.cols, cells.rows, to_full_x, to_full_y,
					       std::max(params.lk_window, 3), params.aperture_ratio);
	if (params.method == GroupFlow::Dis) {
		if (!dis)
			dis = cv::DISOpticalFlow::create(cv::DISOpticalFlow::PRESET_ULTRAFAST);
		cv::Mat flow;
		dis->calc(prev, cur, flow);
		// The mean flow over each cell: an area resize of the flow field to the grid.
		cv::Mat per_cell, back_per_cell;
		cv::resize(flow, per_cell, cv::Size(cells.cols, cells.rows), 0, 0, cv::INTER_AREA);
		const bool round_trip = params.max_round_trip_px > 0;
		if (round_trip) {
			// DIS keeps no state between calls (no temporal initialisation is set), so the same object
			// computes the backward field.
			cv::Mat back;
			dis->calc(cur, prev, back);
			cv::resize(back, back_per_cell, cv::Size(cells.cols, cells.rows), 0, 0, cv::INTER_AREA);
		}
		for (int r = 0; r < cells.rows; ++r)
			for (int c = 0; c < cells.cols; ++c) {
				const cv::Vec2f f = per_cell.at<cv::Vec2f>(r, c);
				const auto i = static_cast<size_t>(r * cells.cols + c);
				cells.flow[i] = {static_cast<float>(f[0] * to_full_x),
						 static_cast<float>(f[1] * to_full_y)};
				bool valid = std::isfinite(f[0]) && std::isfinite(f[1]);
				if (valid && round_trip) {
					// The backward flow of the cell the forward flow leads to should bring it home.
					const int cc = static_cast<int>(std::floor(c + 0.5 + cells.flow[i].x / step));
					const int rr = static_cast<int>(std::floor(r + 0.5 + cells.flow[i].y / step));
					valid = cc >= 0 && rr >= 0 && cc < cells.cols && rr < cells.rows;
					if (valid) {
						const cv::Vec2f b = back_per_cell.at<cv::Vec2f>(rr, cc);
						valid = std::hypot((f[0] + b[0]) * to_full_x,
								   (f[1] + b[1]) * to_full_y) <=
							params.max_round_trip_px;
					}
				}
				cells.valid[i] = valid ? 1 : 0;
			}
		return cells;
	}
	// Seed 002's pyramidal LK at each cell's centre.
	std::vector<cv::Point2f> from(count), to;
	for (int r = 0; r < cells.rows; ++r)
		for (int c = 0; c < cells.cols; ++c)
			from[static_cast<size_t>(r * cells.cols + c)] = {
				static_cast<float>((c + 0.5) * step / to_full_x),
				static_cast<float>((r + 0.5) * step / to_full_y)};
	std::vector<uint8_t> status;
	std::vector<float> error;
	const int window = std::max(params.lk_window, 3);
	cv::calcOpticalFlowPyrLK(prev, cur, from, to, status, error, cv::Size(window, window), params.lk_levels,
				 cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.03), 0,
				 params.lk_min_eigen);
	// Tracked back again: a cell whose round trip misses its start (a flat patch, an occlusion) is not
	// trusted.
	std::vector<cv::Point2f> back;
	std::vector<uint8_t> back_status;
	if (params.max_round_trip_px > 0)
		cv::calcOpticalFlowPyrLK(cur, prev, to, back, back_status, error, cv::Size(window, window),
					 params.lk_levels,
					 cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.03), 0,
					 params.lk_min_eigen);
	for (size_t i = 0; i < count; ++i) {
		// No significant gradient, or lost: the seed zeroes such pixels (flow stays 0, not valid).
		if (status[i] == 0 || !std::isfinite(to[i].x) || !std::isfinite(to[i].y))
			continue;
		if (params.max_round_trip_px > 0 &&
		    (back_status[i] == 0 || cv::norm(back[i] - from[i]) * to_full_x > params.max_round_trip_px))
			continue;
		cells.flow[i] = {static_cast<float>((to[i].x - from[i].x) * to_full_x),
				 static_cast<float>((to[i].y - from[i].y) * to_full_y)};
		cells.valid[i] = 1;
	}
	return cells;
}

std::vector<float> cell_depths(std::span<const cv::KeyPoint> keypoints, std::span<const cv::Vec3f> xyz, int cols,
			       int rows, const DenseFlowParams &params)
{
	const auto count = static_cast<size_t>(std::max(cols, 0)) * static_cast<size_t>(std::max(rows, 0));
	std::vector<float> depth(count, kNaN);
	if (count == 0 || xyz.size() != keypoints.size())
		return depth;
	const int step = std::max(params.step_px, 1);
	// Each cell's own depth (the median of its points), then per cell the median of the own depths around
	// it: a median of medians, which costs a few values per cell instead of every point around it.
	std::vector<std::pair<uint32_t, float>> by_cell;
	by_cell.reserve(keypoints.size());
	for (size_t k = 0; k < keypoints.size(); ++k) {
		if (!(xyz[k][2] > 0) || !std::isfinite(xyz[k][2]))
			continue;
		const int c = static_cast<int>(keypoints[k].pt.x) / step;
		const int r = static_cast<int>(keypoints[k].pt.y) / step;
		if (c >= 0 && r >= 0 && c < cols && r < rows)
			by_cell.emplace_back(static_cast<uint32_t>(r * cols + c), xyz[k][2]);
	}
	std::sort(by_cell.begin(), by_cell.end());
	std::vector<float> own(count, kNaN), values;
	for (size_t a = 0; a < by_cell.size();) {
		size_t b = a;
		values.clear();
		while (b < by_cell.size() && by_cell[b].first == by_cell[a].first)
			values.push_back(by_cell[b++].second);
		own[by_cell[a].first] = median_of(values);
		a = b;
	}
	const int radius = std::max(params.depth_radius_cells, 0);
	for (int r = 0; r < rows; ++r)
		for (int c = 0; c < cols; ++c) {
			values.clear();
			for (int rr = std::max(r - radius, 0); rr <= std::min(r + radius, rows - 1); ++rr)
				for (int cc = std::max(c - radius, 0); cc <= std::min(c + radius, cols - 1); ++cc)
					if (const float z = own[static_cast<size_t>(rr * cols + cc)]; std::isfinite(z))
						values.push_back(z);
			if (values.empty())
				continue;
			const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
			std::nth_element(values.begin(), mid, values.end()); // in place: no copy per cell
			depth[static_cast<size_t>(r * cols + c)] = *mid;
		}
	return depth;
}

std::vector<MotionPoint> cell_motion(const CellFlow &cells, const DenseFlowParams &params,
				     std::span<const float> prev_depth, std::span<const float> cur_depth,
				     const StaticSceneModel &model)
{
	const int step = std::max(params.step_px, 1);
	const bool metric = model.curr_from_prev && model.rig;
	std::vector<MotionPoint> points;
	points.reserve(cells.flow.size());
	for (int r = 0; r < cells.rows; ++r)
		for (int c = 0; c < cells.cols; ++c) {
			const auto i = static_cast<size_t>(r * cells.cols + c);
			const cv::Point2f before(static_cast<float>((c + 0.5) * step),
						 static_cast<float>((r + 0.5) * step));
			MotionPoint m;
			m.flow = cells.flow[i];
			m.px = before + m.flow;
			const float z_prev = i < prev_depth.size() ? prev_depth[i] : kNaN;
			if (metric) {
				m.residual = cv::Point2f(kNaN, kNaN);
				if (std::isfinite(z_prev)) {
					const cv::Vec3d p = model.rig->back_project(before.x, before.y, z_prev);
					if (const auto now = model.rig->project(*model.curr_from_prev * p))
						m.residual = m.px - cv::Point2f(static_cast<float>(now->x),
										static_cast<float>(now->y));
				}
			} else if (model.homography) {
				const cv::Vec3d h = *model.homography * cv::Vec3d(before.x, before.y, 1);
				m.residual = h[2] != 0 ? m.px - cv::Point2f(static_cast<float>(h[0] / h[2]),
									    static_cast<float>(h[1] / h[2]))
						       : cv::Point2f(kNaN, kNaN);
			} else {
				m.residual = m.flow; // no scene model: the static scene stands still
			}
			if (model.rig && std::isfinite(z_prev)) {
				const cv::Vec3d p = model.rig->back_project(before.x, before.y, z_prev);
				m.prev_xyz = cv::Vec3f(p);
				const int cc = static_cast<int>(m.px.x) / step, rr = static_cast<int>(m.px.y) / step;
				if (cc >= 0 && rr >= 0 && cc < cells.cols && rr < cells.rows) {
					const float z = cur_depth.size() > static_cast<size_t>(rr * cells.cols + cc)
								? cur_depth[static_cast<size_t>(rr * cells.cols + cc)]
								: kNaN;
					if (std::isfinite(z))
						m.xyz = cv::Vec3f(model.rig->back_project(m.px.x, m.px.y, z));
				}
			}
			if (i < cells.across.size())
				m.across = cells.across[i];
			if (cells.valid[i] == 0) // kept in place (index = cell), out of the split and the groups
				m.residual = cv::Point2f(kNaN, kNaN);
			points.push_back(m);
		}
	return points;
}

void join_by_cells(std::span<const MotionPoint> points, std::span<const int> group_of_cell, int cols, int rows,
		   int step_px, double still_px, std::vector<int> &group_of_point)
{
	const int step = std::max(step_px, 1);
	for (size_t i = 0; i < points.size() && i < group_of_point.size(); ++i) {
		if (group_of_point[i] >= 0 || !(cv::norm(points[i].residual) >= still_px)) // NaN: no residual
			continue;
		const cv::Point2f before = points[i].px - points[i].flow;
		if (!(before.x >= 0 && before.y >= 0)) // also NaN
			continue;
		const int c = static_cast<int>(before.x) / step, r = static_cast<int>(before.y) / step;
		if (c >= cols || r >= rows)
			continue;
		const auto cell = static_cast<size_t>(r) * static_cast<size_t>(cols) + static_cast<size_t>(c);
		if (cell < group_of_cell.size())
			group_of_point[i] = group_of_cell[cell];
	}
}

std::vector<uint32_t> supported_cells(std::span<const uint32_t> strong, int cols, int rows, int min_neighbours)
{
	if (min_neighbours <= 0 || cols <= 0 || rows <= 0)
		return {strong.begin(), strong.end()};
	std::vector<uint8_t> is_strong(static_cast<size_t>(cols) * static_cast<size_t>(rows), 0);
	for (const uint32_t i : strong)
		if (i < is_strong.size())
			is_strong[i] = 1;
	std::vector<uint32_t> kept;
	for (const uint32_t i : strong) {
		const int r = static_cast<int>(i) / cols, c = static_cast<int>(i) % cols;
		int around = 0;
		for (int dr = -1; dr <= 1; ++dr)
			for (int dc = -1; dc <= 1; ++dc) {
				const int rr = r + dr, cc = c + dc;
				if ((dr != 0 || dc != 0) && rr >= 0 && cc >= 0 && rr < rows && cc < cols)
					around += is_strong[static_cast<size_t>(rr * cols + cc)];
			}
		if (around >= min_neighbours)
			kept.push_back(i);
	}
	return kept;
}

} // namespace stereod::vision
