#include "tools/feature_eval.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/features2d.hpp>

namespace stereod::tools {
namespace {

constexpr double kNormalisedRadius = 30.0;

cv::Point2d apply(const cv::Matx33d &h, cv::Point2d p)
{
	const cv::Vec3d q = h * cv::Vec3d(p.x, p.y, 1);
	return {q[0] / q[2], q[1] / q[2]};
}

/// The local affine part of h at p: the Jacobian of the projective map.
cv::Matx22d jacobian(const cv::Matx33d &h, cv::Point2d p)
{
	const double w = h(2, 0) * p.x + h(2, 1) * p.y + h(2, 2);
	const double u = h(0, 0) * p.x + h(0, 1) * p.y + h(0, 2);
	const double v = h(1, 0) * p.x + h(1, 1) * p.y + h(1, 2);
	return cv::Matx22d((h(0, 0) * w - u * h(2, 0)) / (w * w), (h(0, 1) * w - u * h(2, 1)) / (w * w),
			   (h(1, 0) * w - v * h(2, 0)) / (w * w), (h(1, 1) * w - v * h(2, 1)) / (w * w));
}

bool inside(cv::Point2d p, cv::Size size)
{
	return p.x >= 0 && p.y >= 0 && p.x < size.width && p.y < size.height;
}

} // namespace

double QualityScore::repeatability() const
{
	const size_t n = std::min(keypoints_1, keypoints_2);
	return n == 0 ? 0.0 : static_cast<double>(correspondences) / static_cast<double>(n);
}

double QualityScore::matching_score() const
{
	const size_t n = std::min(keypoints_1, keypoints_2);
	return n == 0 ? 0.0 : static_cast<double>(correct_matches) / static_cast<double>(n);
}

double ellipse_overlap_error(const cv::Matx22d &m1, cv::Point2d c1, const cv::Matx22d &m2, cv::Point2d c2)
{
	// Bounding boxes from the ellipses' extents: half-width sqrt((M^-1)_00), half-height sqrt((M^-1)_11).
	const cv::Matx22d i1 = m1.inv(), i2 = m2.inv();
	const double x0 = std::min(c1.x - std::sqrt(i1(0, 0)), c2.x - std::sqrt(i2(0, 0)));
	const double x1 = std::max(c1.x + std::sqrt(i1(0, 0)), c2.x + std::sqrt(i2(0, 0)));
	const double y0 = std::min(c1.y - std::sqrt(i1(1, 1)), c2.y - std::sqrt(i2(1, 1)));
	const double y1 = std::max(c1.y + std::sqrt(i1(1, 1)), c2.y + std::sqrt(i2(1, 1)));
	const double step = std::max(x1 - x0, y1 - y0) / 80.0;
	size_t in_both = 0, in_either = 0;
	for (double y = y0; y <= y1; y += step)
		for (double x = x0; x <= x1; x += step) {
			const cv::Vec2d d1(x - c1.x, y - c1.y), d2(x - c2.x, y - c2.y);
			const bool a = d1.dot(m1 * d1) <= 1.0, b = d2.dot(m2 * d2) <= 1.0;
			in_both += a && b;
			in_either += a || b;
		}
	return in_either == 0 ? 1.0 : 1.0 - static_cast<double>(in_both) / static_cast<double>(in_either);
}

QualityScore evaluate_quality(const Features &f1, cv::Size size1, const Features &f2, cv::Size size2,
			      const cv::Matx33d &h_1to2, double max_overlap_error)
{
	const cv::Matx33d h_2to1 = h_1to2.inv();
	std::vector<int> common1, common2;
	for (int i = 0; i < static_cast<int>(f1.keypoints.size()); ++i)
		if (inside(apply(h_1to2, f1.keypoints[static_cast<size_t>(i)].pt), size2))
			common1.push_back(i);
	for (int j = 0; j < static_cast<int>(f2.keypoints.size()); ++j)
		if (inside(apply(h_2to1, f2.keypoints[static_cast<size_t>(j)].pt), size1))
			common2.push_back(j);
	QualityScore score;
	score.keypoints_1 = common1.size();
	score.keypoints_2 = common2.size();

	// Overlap errors of every plausible pair (centres close relative to the region size).
	struct Pair {
		int i, j;
		double error;
	};
	std::vector<Pair> pairs;
	std::vector<std::vector<std::pair<int, double>>> errors_of(f1.keypoints.size());
	for (int i : common1) {
		const cv::KeyPoint &k1 = f1.keypoints[static_cast<size_t>(i)];
		const cv::Point2d c1 = apply(h_1to2, k1.pt);
		const cv::Matx22d a = jacobian(h_1to2, k1.pt);
		const double r1 = std::max(k1.size / 2.0, 1.0);
		// Circle of radius r1 mapped by A: M = A^-T A^-1 / r1^2. Normalise so it has radius ~30.
		const cv::Matx22d a_inv = a.inv();
		const cv::Matx22d m1 = a_inv.t() * a_inv * (1.0 / (r1 * r1));
		const double mapped_radius = r1 * std::sqrt(std::abs(cv::determinant(a)));
		const double f = kNormalisedRadius / mapped_radius;
		for (int j : common2) {
			const cv::KeyPoint &k2 = f2.keypoints[static_cast<size_t>(j)];
			const double r2 = std::max(k2.size / 2.0, 1.0);
			const double distance = cv::norm(cv::Point2d(k2.pt) - c1);
			if (distance > 2.0 * (mapped_radius + r2))
				continue;
			const cv::Matx22d m2 = cv::Matx22d::eye() * (1.0 / (r2 * r2));
			// Normalising: scale coordinates by f, so M becomes M / f^2, centres scale with f.
			const double error = ellipse_overlap_error(m1 * (1.0 / (f * f)), c1 * f, m2 * (1.0 / (f * f)),
								   cv::Point2d(k2.pt) * f);
			if (error < max_overlap_error) {
				pairs.push_back({i, j, error});
				errors_of[static_cast<size_t>(i)].emplace_back(j, error);
			}
		}
	}
	// One-to-one: greedily by increasing overlap error.
	std::sort(pairs.begin(), pairs.end(), [](const Pair &a, const Pair &b) { return a.error < b.error; });
	std::vector<bool> used1(f1.keypoints.size(), false), used2(f2.keypoints.size(), false);
	for (const auto &p : pairs) {
		if (used1[static_cast<size_t>(p.i)] || used2[static_cast<size_t>(p.j)])
			continue;
		used1[static_cast<size_t>(p.i)] = used2[static_cast<size_t>(p.j)] = true;
		++score.correspondences;
	}

	// Matching score: the nearest neighbour in descriptor space among image 2's common keypoints.
	if (!f1.descriptors.empty() && !f2.descriptors.empty() && !common1.empty() && !common2.empty()) {
		cv::Mat d1, d2;
		for (int i : common1)
			d1.push_back(f1.descriptors.row(i));
		for (int j : common2)
			d2.push_back(f2.descriptors.row(j));
		cv::BFMatcher matcher(f1.norm);
		std::vector<cv::DMatch> nn;
		matcher.match(d1, d2, nn);
		for (const auto &m : nn) {
			const int i = common1[static_cast<size_t>(m.queryIdx)],
				  j = common2[static_cast<size_t>(m.trainIdx)];
			const auto &errors = errors_of[static_cast<size_t>(i)];
			score.correct_matches +=
				std::any_of(errors.begin(), errors.end(), [&](const auto &e) { return e.first == j; });
		}
	}
	return score;
}

} // namespace stereod::tools
