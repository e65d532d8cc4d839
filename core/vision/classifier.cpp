#include "core/vision/classifier.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/calib3d.hpp>

#include "core/vision/features.hpp"

namespace stereod::vision {

std::optional<HomographyFit> fit_homography(std::span<const cv::Point2f> from, std::span<const cv::Point2f> to,
					    double ransac_threshold_px, int min_points)
{
	if (from.size() != to.size() || from.size() < static_cast<size_t>(std::max(min_points, 4)))
		return std::nullopt;
	const std::vector<cv::Point2f> src(from.begin(), from.end());
	const std::vector<cv::Point2f> dst(to.begin(), to.end());
	std::vector<uchar> mask;
	// A fixed RNG state inside findHomography keeps results repeatable run to run.
	cv::Mat h = cv::findHomography(src, dst, cv::RANSAC, ransac_threshold_px, mask, 2000, 0.995);
	if (h.empty())
		return std::nullopt;
	HomographyFit fit;
	fit.h = cv::Matx33d(h);
	fit.inliers.resize(mask.size());
	for (size_t i = 0; i < mask.size(); ++i) {
		fit.inliers[i] = mask[i] != 0;
		fit.inlier_count += mask[i] != 0 ? 1 : 0;
	}
	if (fit.inlier_count < 4)
		return std::nullopt;
	return fit;
}

cv::Point2f project(const cv::Matx33d &h, cv::Point2f p)
{
	const cv::Vec3d q = h * cv::Vec3d(p.x, p.y, 1.0);
	if (std::abs(q[2]) < 1e-12)
		return {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity()};
	return {static_cast<float>(q[0] / q[2]), static_cast<float>(q[1] / q[2])};
}

double reprojection_error(const cv::Matx33d &h, cv::Point2f prev, cv::Point2f cur)
{
	const cv::Vec3d q = h * cv::Vec3d(prev.x, prev.y, 1.0);
	if (std::abs(q[2]) < 1e-12)
		return std::numeric_limits<double>::infinity();
	const double w = q[2];
	const double rx = static_cast<double>(cur.x) - q[0] / w;
	const double ry = static_cast<double>(cur.y) - q[1] / w;
	// A = d(H x)/dx, the 2x2 Jacobian of the projected point; the residual's covariance over sigma^2 is
	// A A^T (noise at x carried through H) + I (noise at x').
	double a[2][2];
	for (int r = 0; r < 2; ++r)
		for (int c = 0; c < 2; ++c)
			a[r][c] = (h(r, c) * w - q[r] * h(2, c)) / (w * w);
	const double s00 = a[0][0] * a[0][0] + a[0][1] * a[0][1] + 1.0;
	const double s01 = a[0][0] * a[1][0] + a[0][1] * a[1][1];
	const double s11 = a[1][0] * a[1][0] + a[1][1] * a[1][1] + 1.0;
	const double det = s00 * s11 - s01 * s01; // >= 1: A A^T is positive semi-definite
	return (s11 * rx * rx - 2.0 * s01 * rx * ry + s00 * ry * ry) / det;
}

bool passes_reprojection(double error_px2, const ClassifierParams &params)
{
	const double sigma2 = params.reprojection_sigma_px * params.reprojection_sigma_px;
	return std::isfinite(error_px2) && error_px2 / sigma2 < params.reprojection_chi2;
}

bool AreaWindow::contains(cv::Point2f displacement) const
{
	const double du2 = static_cast<double>(displacement.x) * displacement.x;
	const double dv2 = static_cast<double>(displacement.y) * displacement.y;
	return du2 <= std::max(theta * max_du2, floor_px2) && dv2 <= std::max(eta * max_dv2, floor_px2);
}

AreaWindow area_window(std::span<const cv::Point2f> displacements, double theta, double eta, double floor_px)
{
	AreaWindow window;
	window.theta = theta;
	window.eta = eta;
	window.floor_px2 = floor_px * floor_px;
	for (const auto &d : displacements) {
		window.max_du2 = std::max(window.max_du2, static_cast<double>(d.x) * d.x);
		window.max_dv2 = std::max(window.max_dv2, static_cast<double>(d.y) * d.y);
	}
	return window;
}

double texture_distance(const cv::Vec3f &a, const cv::Vec3f &b, const ClassifierParams &params)
{
	// Colours are stored B,G,R (OpenCV order); the seed's weights are given for R,G,B.
	return params.alpha * std::abs(static_cast<double>(a[2] - b[2])) +
	       params.beta * std::abs(static_cast<double>(a[1] - b[1])) +
	       params.gamma * std::abs(static_cast<double>(a[0] - b[0]));
}

double texture_distance_near(const cv::Vec3f &colour, const cv::Mat &image, cv::Point2f at,
			     const ClassifierParams &params)
{
	const int t = params.texture_tolerance_px;
	double best = std::numeric_limits<double>::infinity();
	for (int dy = -t; dy <= t; ++dy)
		for (int dx = -t; dx <= t; ++dx)
			best = std::min(best, texture_distance(colour,
							       sample_colour(image,
									     at + cv::Point2f(static_cast<float>(dx),
											      static_cast<float>(dy)),
									     params.colour_radius),
							       params));
	return best;
}

Classification classify(std::span<const PointPair> pairs, const cv::Mat &cur_image, const ClassifierParams &params,
			std::span<const uint8_t> known_moving)
{
	Classification out;
	const size_t n = pairs.size();
	out.labels.assign(n, PointLabel::Uncertain);
	out.counts.matches = static_cast<int>(n);

	std::vector<cv::Point2f> prev_pts(n), cur_pts(n), displacement(n);
	for (size_t i = 0; i < n; ++i) {
		prev_pts[i] = pairs[i].prev;
		cur_pts[i] = pairs[i].cur;
		displacement[i] = pairs[i].cur - pairs[i].prev;
	}

	bool use_memory = known_moving.size() == n;
	auto votes = [&](size_t i) { return !use_memory || known_moving[i] == 0; };

	// 1. Initial homography over every match (Table 1), but for the points known to move. When the memory
	// calls so many points moving that too few are left to fit, it is not trusted for this frame: fit over
	// every match, as the seed does (otherwise the whole frame would fall to `uncertain`).
	std::optional<HomographyFit> initial;
	auto fit_initial = [&] {
		std::vector<cv::Point2f> from, to;
		for (size_t i = 0; i < n; ++i) {
			if (votes(i)) {
				from.push_back(prev_pts[i]);
				to.push_back(cur_pts[i]);
			}
		}
		return fit_homography(from, to, params.ransac_threshold_px, params.min_matches);
	};
	initial = fit_initial();
	if (!initial && use_memory && n >= static_cast<size_t>(std::max(params.min_matches, 4))) {
		use_memory = false;
		out.fitted_with_known_movers = true;
		initial = fit_initial();
	}
	if (!initial)
		return out;
	const cv::Matx33d h1 = initial->h;

	// 2. Eq. 1 against the Mahalanobis gate.
	std::vector<size_t> static_set, uncertain_set;
	for (size_t i = 0; i < n; ++i) {
		if (passes_reprojection(reprojection_error(h1, prev_pts[i], cur_pts[i]), params))
			static_set.push_back(i);
		else
			uncertain_set.push_back(i);
	}
	out.counts.initial_static = static_cast<int>(static_set.size());
	out.counts.initial_uncertain = static_cast<int>(uncertain_set.size());

	// 3. Static area constraint: the window comes from the largest displacements over the frame pair.
	const AreaWindow static_window =
		area_window(displacement, params.static_theta, params.static_eta, params.area_floor_px);
	std::erase_if(static_set, [&](size_t i) { return !static_window.contains(displacement[i]); });
	out.counts.static_after_area = static_cast<int>(static_set.size());

	// 4. Static texture constraint (eqs. 2-4): the two ends of a static match look alike. Evaluated once for
	// every pair: step 6 and the motion memory ask the same question.
	out.texture_agrees.resize(n);
	for (size_t i = 0; i < n; ++i)
		out.texture_agrees[i] = texture_distance_near(pairs[i].prev_colour, cur_image, pairs[i].cur, params) <
					params.texture_threshold;
	auto same_texture = [&](size_t i) { return out.texture_agrees[i] != 0; };
	std::erase_if(static_set, [&](size_t i) { return !same_texture(i); });
	out.counts.static_after_texture = static_cast<int>(static_set.size());
	for (size_t i : static_set)
		out.labels[i] = PointLabel::Static;

	// 5. The homography again, from the refined static set only.
	cv::Matx33d h2 = h1;
	int h2_inliers = initial->inlier_count;
	{
		std::vector<cv::Point2f> from, to;
		for (size_t i : static_set) {
			if (votes(i)) {
				from.push_back(prev_pts[i]);
				to.push_back(cur_pts[i]);
			}
		}
		if (auto refined = fit_homography(from, to, params.ransac_threshold_px, params.min_matches)) {
			h2 = refined->h;
			h2_inliers = refined->inlier_count;
			out.homography_refined = true;
		}
	}
	out.homography = h2;
	out.homography_inliers = h2_inliers;

	// 6. Second re-projection of the uncertain points with the refined homography.
	std::vector<size_t> dynamic_set;
	for (size_t i : uncertain_set) {
		if (passes_reprojection(reprojection_error(h2, prev_pts[i], cur_pts[i]), params)) {
			// The better homography explains it: static, if its texture agrees too.
			if (same_texture(i)) {
				out.labels[i] = PointLabel::Static;
				++out.counts.second_static;
			}
			continue;
		}
		dynamic_set.push_back(i);
	}
	out.counts.dynamic_candidates = static_cast<int>(dynamic_set.size());

	// 7. Dynamic area constraint on the motion relative to the static scene (p - Hx): its window comes
	// from all dynamic candidates, and no mover jumps farther than dynamic_max_motion_px.
	std::vector<cv::Point2f> projected(n), own_motion;
	for (size_t i : dynamic_set) {
		projected[i] = project(h2, prev_pts[i]);
		own_motion.push_back(cur_pts[i] - projected[i]);
	}
	const AreaWindow dynamic_window =
		area_window(own_motion, params.dynamic_theta, params.dynamic_eta, params.area_floor_px);
	const double max_motion2 = params.dynamic_max_motion_px * params.dynamic_max_motion_px;
	std::erase_if(dynamic_set, [&](size_t i) {
		const cv::Point2f motion = cur_pts[i] - projected[i];
		return !dynamic_window.contains(motion) || static_cast<double>(motion.dot(motion)) > max_motion2;
	});
	out.counts.dynamic_after_area = static_cast<int>(dynamic_set.size());

	// 8. Double texture constraint (eqs. 6-7): the point i looks like its match p (d_n < T) but not like
	// what the static scene now shows at its projection j (dd_n > T). "Looks like" is step 4's test, with
	// its +-1 px tolerance for where a detector puts a corner. "Looks different" is taken at j itself: asking
	// it to differ at every position within a pixel of j would let any fine texture pass for a match by
	// chance (on the unit test's fine-textured mover only 19 of its 35 points stayed dynamic that way).
	for (size_t i : dynamic_set) {
		const cv::Point2f j = projected[i];
		if (j.x < 0 || j.y < 0 || j.x >= static_cast<float>(cur_image.cols) ||
		    j.y >= static_cast<float>(cur_image.rows))
			continue; // j left the image: eq. 6 cannot be evaluated, the point stays a mismatch
		const bool d_n_below = same_texture(i);
		const double dd_n = texture_distance(pairs[i].prev_colour,
						     sample_colour(cur_image, j, params.colour_radius), params);
		if (d_n_below && dd_n > params.texture_threshold) {
			out.labels[i] = PointLabel::Dynamic;
			++out.counts.dynamic;
		}
	}
	return out;
}

} // namespace stereod::vision
