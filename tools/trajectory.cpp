#include "tools/trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace stereod::tools {

namespace {

constexpr double kDegrees = 180.0 / std::numbers::pi;

std::string where(const std::string &path, size_t line)
{
	return path + ":" + std::to_string(line) + ": ";
}

} // namespace

std::vector<StampedPose> read_tum(const std::string &path)
{
	std::ifstream in(path);
	if (!in)
		throw std::runtime_error(path + ": cannot open");
	std::vector<StampedPose> poses;
	std::string text;
	size_t line = 0;
	while (std::getline(in, text)) {
		++line;
		if (text.empty() || text[0] == '#')
			continue;
		std::istringstream fields(text);
		double t, x, y, z, qx, qy, qz, qw;
		if (!(fields >> t >> x >> y >> z >> qx >> qy >> qz >> qw))
			throw std::runtime_error(where(path, line) +
						 "expected 8 numbers: timestamp tx ty tz qx qy qz qw");
		StampedPose p;
		p.t_s = t;
		try {
			p.pose.r = geometry::rotation_from_quaternion(qx, qy, qz, qw);
		} catch (const std::invalid_argument &e) {
			throw std::runtime_error(where(path, line) + e.what());
		}
		p.pose.t = {x, y, z};
		poses.push_back(p);
	}
	return poses;
}

void write_tum(const std::string &path, const std::vector<StampedPose> &poses)
{
	std::ofstream out(path, std::ios::trunc);
	if (!out)
		throw std::runtime_error(path + ": cannot write");
	out << "# timestamp tx ty tz qx qy qz qw (world from camera; x right, y down, z forward)\n";
	out << std::setprecision(10);
	for (const auto &p : poses) {
		const auto q = geometry::quaternion_from_rotation(p.pose.r);
		out << std::fixed << std::setprecision(6) << p.t_s << std::defaultfloat << std::setprecision(10) << ' '
		    << p.pose.t[0] << ' ' << p.pose.t[1] << ' ' << p.pose.t[2] << ' ' << q[0] << ' ' << q[1] << ' '
		    << q[2] << ' ' << q[3] << '\n';
	}
}

std::vector<StampedPose> read_kitti_poses(const std::string &path)
{
	std::ifstream in(path);
	if (!in)
		throw std::runtime_error(path + ": cannot open");
	std::vector<StampedPose> poses;
	std::string text;
	size_t line = 0;
	while (std::getline(in, text)) {
		++line;
		if (text.find_first_not_of(" \t\r") == std::string::npos)
			continue;
		std::istringstream fields(text);
		std::array<double, 12> m{};
		for (double &v : m)
			if (!(fields >> v))
				throw std::runtime_error(where(path, line) +
							 "expected 12 numbers (a row-major 3x4 pose)");
		StampedPose p;
		p.t_s = static_cast<double>(poses.size());
		for (int r = 0; r < 3; ++r) {
			for (int c = 0; c < 3; ++c)
				p.pose.r(r, c) = m[static_cast<size_t>(r * 4 + c)];
			p.pose.t[r] = m[static_cast<size_t>(r * 4 + 3)];
		}
		poses.push_back(p);
	}
	return poses;
}

Association associate(const std::vector<StampedPose> &estimate, const std::vector<StampedPose> &truth, double max_dt_s)
{
	std::vector<StampedPose> sorted = truth;
	std::sort(sorted.begin(), sorted.end(), [](const auto &a, const auto &b) { return a.t_s < b.t_s; });
	std::vector<bool> used(sorted.size(), false);
	Association out;
	for (const auto &e : estimate) {
		const auto it = std::lower_bound(sorted.begin(), sorted.end(), e.t_s,
						 [](const StampedPose &p, double t) { return p.t_s < t; });
		size_t best = sorted.size();
		double best_dt = max_dt_s;
		for (auto candidate : {it, it == sorted.begin() ? it : it - 1}) {
			if (candidate == sorted.end())
				continue;
			const auto k = static_cast<size_t>(candidate - sorted.begin());
			const double dt = std::abs(candidate->t_s - e.t_s);
			if (!used[k] && dt <= best_dt) {
				best = k;
				best_dt = dt;
			}
		}
		if (best == sorted.size())
			continue;
		used[best] = true;
		out.estimate.push_back(e.pose);
		out.truth.push_back(sorted[best].pose);
		out.t_s.push_back(e.t_s);
	}
	return out;
}

ErrorStats error_stats(std::vector<double> values)
{
	ErrorStats s;
	s.count = values.size();
	if (values.empty())
		return s;
	double sum = 0, sum2 = 0;
	for (double v : values) {
		sum += v;
		sum2 += v * v;
		s.max = std::max(s.max, v);
	}
	const double n = static_cast<double>(values.size());
	s.mean = sum / n;
	s.rmse = std::sqrt(sum2 / n);
	s.std = std::sqrt(std::max(0.0, sum2 / n - s.mean * s.mean));
	std::sort(values.begin(), values.end());
	s.median = values.size() % 2 == 1 ? values[values.size() / 2]
					  : (values[values.size() / 2 - 1] + values[values.size() / 2]) / 2;
	return s;
}

geometry::Pose align_rigid(const std::vector<geometry::Pose> &estimate, const std::vector<geometry::Pose> &truth)
{
	const size_t n = std::min(estimate.size(), truth.size());
	if (n == 0)
		return {};
	cv::Vec3d mean_e(0, 0, 0), mean_t(0, 0, 0);
	for (size_t i = 0; i < n; ++i) {
		mean_e += estimate[i].t;
		mean_t += truth[i].t;
	}
	mean_e *= 1.0 / static_cast<double>(n);
	mean_t *= 1.0 / static_cast<double>(n);
	cv::Matx33d covariance = cv::Matx33d::zeros();
	for (size_t i = 0; i < n; ++i)
		covariance += (truth[i].t - mean_t) * (estimate[i].t - mean_e).t();
	cv::Mat w, u, vt;
	cv::SVD::compute(cv::Mat(covariance), w, u, vt);
	const cv::Matx33d U(u), Vt(vt);
	cv::Matx33d s = cv::Matx33d::eye();
	if (cv::determinant(U * Vt) < 0)
		s(2, 2) = -1; // a reflection is not a motion
	geometry::Pose a;
	a.r = U * s * Vt;
	a.t = mean_t - a.r * mean_e;
	return a;
}

AbsoluteError absolute_trajectory_error(const std::vector<geometry::Pose> &estimate,
					const std::vector<geometry::Pose> &truth)
{
	AbsoluteError out;
	out.alignment = align_rigid(estimate, truth);
	std::vector<double> errors;
	for (size_t i = 0; i < std::min(estimate.size(), truth.size()); ++i) {
		const cv::Vec3d d = out.alignment * estimate[i].t - truth[i].t;
		errors.push_back(cv::norm(d));
	}
	out.translation_m = error_stats(std::move(errors));
	return out;
}

RelativeError relative_pose_error(const std::vector<geometry::Pose> &estimate, const std::vector<geometry::Pose> &truth,
				  size_t delta)
{
	RelativeError out;
	std::vector<double> translation, rotation;
	const size_t n = std::min(estimate.size(), truth.size());
	for (size_t i = 0; delta > 0 && i + delta < n; ++i) {
		const geometry::Pose truth_rel = truth[i].inverse() * truth[i + delta];
		const geometry::Pose est_rel = estimate[i].inverse() * estimate[i + delta];
		const geometry::Pose error = truth_rel.inverse() * est_rel;
		translation.push_back(error.distance());
		rotation.push_back(error.angle() * kDegrees);
	}
	out.translation_m = error_stats(std::move(translation));
	out.rotation_deg = error_stats(std::move(rotation));
	return out;
}

Drift drift(const std::vector<geometry::Pose> &estimate, const std::vector<geometry::Pose> &truth, size_t window,
	    double min_distance_m)
{
	Drift out;
	const size_t n = std::min(estimate.size(), truth.size());
	double sum_t = 0, sum_r = 0;
	for (size_t i = 0; window > 0 && i + window < n; ++i) {
		double distance = 0;
		for (size_t k = i; k < i + window; ++k)
			distance += cv::norm(truth[k + 1].t - truth[k].t);
		if (distance < min_distance_m)
			continue;
		const geometry::Pose truth_rel = truth[i].inverse() * truth[i + window];
		const geometry::Pose est_rel = estimate[i].inverse() * estimate[i + window];
		const geometry::Pose error = truth_rel.inverse() * est_rel;
		sum_t += error.distance() / distance;
		sum_r += error.angle() * kDegrees / distance;
		++out.windows;
	}
	if (out.windows > 0) {
		out.translation_percent = 100 * sum_t / static_cast<double>(out.windows);
		out.rotation_deg_per_m = sum_r / static_cast<double>(out.windows);
	}
	return out;
}

} // namespace stereod::tools
