#include "core/vision/ego.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>

#include <opencv2/calib3d.hpp>

namespace stereod::vision {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
/// Estimation noise on top of the acceleration bounds: the previous motion the prior extrapolates is itself
/// measured to about this.
constexpr double kPriorSlackM = 0.003;
constexpr double kPriorSlackRad = 0.001;

/// Squared re-projection error of point i under `pose`; infinite when it lands behind the camera.
double error2(const std::vector<cv::Point3f> &object, const std::vector<cv::Point2f> &image, size_t i,
	      const geometry::StereoRig &rig, const geometry::Pose &pose)
{
	const auto p = rig.project(pose * cv::Vec3d(object[i].x, object[i].y, object[i].z));
	if (!p)
		return std::numeric_limits<double>::infinity();
	const double dx = p->x - image[i].x, dy = p->y - image[i].y;
	return dx * dx + dy * dy;
}

/// RANSAC's score of a hypothesis: how many points it explains and over how many cells of a coarse image
/// grid they spread. Counted without building the list.
struct Support {
	size_t points = 0;
	size_t cells = 0;
};

/// The coarse grid the support's spread is counted on: kSupportCols x kSupportRows cells over the image
/// (twice the principal point).
constexpr int kSupportCols = 16, kSupportRows = 12;

Support count_inliers(const std::vector<cv::Point3f> &object, const std::vector<cv::Point2f> &image,
		      const geometry::StereoRig &rig, const geometry::Pose &pose, double threshold_px)
{
	Support support;
	std::array<uint8_t, kSupportCols * kSupportRows> occupied{};
	const double cell_w = std::max(2 * rig.cx / kSupportCols, 1.0),
		     cell_h = std::max(2 * rig.cy / kSupportRows, 1.0);
	for (size_t i = 0; i < object.size(); ++i) {
		if (!(error2(object, image, i, rig, pose) <= threshold_px * threshold_px))
			continue;
		++support.points;
		const int c = std::clamp(static_cast<int>(image[i].x / cell_w), 0, kSupportCols - 1);
		const int r = std::clamp(static_cast<int>(image[i].y / cell_h), 0, kSupportRows - 1);
		uint8_t &cell = occupied[static_cast<size_t>(r * kSupportCols + c)];
		support.cells += cell == 0 ? 1 : 0;
		cell = 1;
	}
	return support;
}

std::vector<int> inliers_of(const std::vector<cv::Point3f> &object, const std::vector<cv::Point2f> &image,
			    const geometry::StereoRig &rig, const geometry::Pose &pose, double threshold_px,
			    double &rms_px)
{
	std::vector<int> inliers;
	double sum2 = 0;
	for (size_t i = 0; i < object.size(); ++i) {
		const double e2 = error2(object, image, i, rig, pose);
		if (e2 <= threshold_px * threshold_px) {
			inliers.push_back(static_cast<int>(i));
			sum2 += e2;
		}
	}
	rms_px = inliers.empty() ? 0 : std::sqrt(sum2 / static_cast<double>(inliers.size()));
	return inliers;
}

geometry::Pose pose_of(const cv::Mat &rvec, const cv::Mat &tvec)
{
	geometry::Pose pose;
	pose.r = geometry::rotation_from_vector(cv::Vec3d(rvec));
	pose.t = cv::Vec3d(tvec);
	return pose;
}

/// Levenberg-Marquardt on the inliers of `start`, then the inliers again with the refined pose, and once more.
/// A round whose pose `keep` refuses, or that leaves fewer than `min_inliers`, is not taken. Returns the pose;
/// `inliers` are its inliers as last selected.
template <typename Keep>
geometry::Pose refine_on_inliers(const std::vector<cv::Point3f> &object, const std::vector<cv::Point2f> &image,
				 const geometry::StereoRig &rig, const geometry::Pose &start, double threshold_px,
				 int min_inliers, Keep keep, std::vector<int> &inliers)
{
	cv::Mat rvec = cv::Mat(geometry::vector_from_rotation(start.r)).clone();
	cv::Mat tvec = cv::Mat(start.t).clone();
	for (int round = 0; round < 2; ++round) {
		std::vector<cv::Point3f> in_object;
		std::vector<cv::Point2f> in_image;
		for (int i : inliers) {
			in_object.push_back(object[static_cast<size_t>(i)]);
			in_image.push_back(image[static_cast<size_t>(i)]);
		}
		cv::Mat r = rvec.clone(), t = tvec.clone();
		cv::solvePnPRefineLM(in_object, in_image, rig.k(), cv::noArray(), r, t);
		const geometry::Pose refined = pose_of(r, t);
		if (!keep(refined))
			break;
		double rms = 0;
		std::vector<int> support = inliers_of(object, image, rig, refined, threshold_px, rms);
		if (static_cast<int>(support.size()) < min_inliers)
			break;
		rvec = r, tvec = t;
		inliers = std::move(support);
	}
	return pose_of(rvec, tvec);
}

/// One RANSAC fit and its refinement at one inlier distance.
struct PoseFit {
	geometry::Pose pose;
	std::vector<int> inliers; ///< indices into the fit's points
	double rms_px = 0;	  ///< re-projection RMS over the inliers
	double threshold_px = 0;
	int samples = 0;
};

/// RANSAC over P3P hypotheses that `plausible` accepts, scored by EgoParams::ransac_spread_score, then
/// Levenberg-Marquardt on the best one's inliers (refine_on_inliers). Nothing when no hypothesis had an
/// inlier.
template <typename Plausible>
std::optional<PoseFit> fit_pose(const std::vector<cv::Point3f> &object, const std::vector<cv::Point2f> &image,
				const geometry::StereoRig &rig, const EgoParams &params, double threshold_px,
				Plausible plausible)
{
	PoseFit fit;
	fit.threshold_px = threshold_px;
	const cv::Matx33d k = rig.k();
	std::mt19937 rng(0x5eed);
	std::uniform_int_distribution<size_t> pick(0, object.size() - 1);
	size_t best_support = 0, best_cells = 0;
	geometry::Pose best;
	// Samples needed: with a fraction w of inliers, one sample of 3 is all inliers with probability w^3, so
	// log(1 - confidence) / log(1 - w^3) samples find one with the wanted confidence. At least a few are drawn
	// so that a lucky first hypothesis on a mover does not end the search.
	constexpr int kMinSamples = 12;
	int needed = params.ransac_iterations;
	const auto samples_for = [&](size_t support) {
		const double w = static_cast<double>(support) / static_cast<double>(object.size());
		const double miss = 1.0 - w * w * w;
		if (params.ransac_confidence <= 0 || params.ransac_confidence >= 1)
			return params.ransac_iterations;
		if (miss <= 1e-12)
			return std::min(kMinSamples, params.ransac_iterations);
		const double samples = std::ceil(std::log(1.0 - params.ransac_confidence) / std::log(miss));
		return static_cast<int>(std::clamp(samples,
						   static_cast<double>(std::min(kMinSamples, params.ransac_iterations)),
						   static_cast<double>(params.ransac_iterations)));
	};
	for (int iteration = 0; iteration < needed; ++iteration) {
		fit.samples = iteration + 1;
		std::array<size_t, 3> sample{};
		sample[0] = pick(rng);
		do
			sample[1] = pick(rng);
		while (sample[1] == sample[0]);
		do
			sample[2] = pick(rng);
		while (sample[2] == sample[0] || sample[2] == sample[1]);
		std::vector<cv::Point3f> sample_object;
		std::vector<cv::Point2f> sample_image;
		for (size_t i : sample) {
			sample_object.push_back(object[i]);
			sample_image.push_back(image[i]);
		}
		std::vector<cv::Mat> rvecs, tvecs;
		const int solutions =
			cv::solveP3P(sample_object, sample_image, k, cv::noArray(), rvecs, tvecs, cv::SOLVEPNP_AP3P);
		for (int solution = 0; solution < solutions; ++solution) {
			const geometry::Pose hypothesis =
				pose_of(rvecs[static_cast<size_t>(solution)], tvecs[static_cast<size_t>(solution)]);
			if (!plausible(hypothesis))
				continue;
			const Support support = count_inliers(object, image, rig, hypothesis, threshold_px);
			// By spread first: a mover is a compact patch of many points, the static scene spreads over the
			// image, so a hypothesis that explains a far wall and a mover passing in front of it (the two
			// look alike when a rotation trades for a translation) loses to one explaining the wall and the
			// sparse ground below.
			const bool better = params.ransac_spread_score ? std::pair(support.cells, support.points) >
										 std::pair(best_cells, best_support)
								       : support.points > best_support;
			if (better) {
				best_support = support.points;
				best_cells = support.cells;
				best = hypothesis;
				needed = samples_for(support.points);
			}
		}
	}
	if (best_support == 0)
		return std::nullopt;
	fit.pose = best;
	fit.inliers = inliers_of(object, image, rig, best, threshold_px, fit.rms_px);
	if (static_cast<int>(fit.inliers.size()) < params.min_inliers)
		return fit;
	// A refinement that leaves the bounds (it slid towards a mover among the inliers) is not taken.
	fit.pose =
		refine_on_inliers(object, image, rig, best, threshold_px, params.min_inliers, plausible, fit.inliers);
	fit.inliers = inliers_of(object, image, rig, fit.pose, threshold_px, fit.rms_px);
	return fit;
}

/// Per-axis noise of a static point's residual under `pose`, from the median residual of every candidate,
/// movers included: unlike the inliers' RMS it is not cut at the RANSAC threshold, and movers are a minority
/// of the points that vote (a 2-d Gaussian's norm has median 1.1774 sigma).
double residual_sigma(const std::vector<cv::Point3f> &object, const std::vector<cv::Point2f> &image,
		      const geometry::StereoRig &rig, const geometry::Pose &pose)
{
	std::vector<double> norms(object.size());
	for (size_t i = 0; i < object.size(); ++i)
		norms[i] = std::sqrt(error2(object, image, i, rig, pose));
	if (norms.empty())
		return 0;
	const auto mid = norms.begin() + static_cast<std::ptrdiff_t>(norms.size() / 2);
	std::nth_element(norms.begin(), mid, norms.end());
	constexpr double kRayleighMedian = 1.1774100225154747; // sqrt(2 ln 2)
	return std::isfinite(*mid) ? *mid / kRayleighMedian : 0;
}

} // namespace

double normal_quantile(double p)
{
	// Acklam's rational approximation (relative error 1.15e-9), then one Halley step on the CDF, which takes
	// it to double precision. It used to be 100 bisection steps of erfc, and the gates call it for every
	// point of every frame: 4-5 % of the daemon's CPU on the sim.
	if (!(p > 0 && p < 1))
		return p == 0 ? -std::numeric_limits<double>::infinity()
			      : (p == 1 ? std::numeric_limits<double>::infinity()
					: std::numeric_limits<double>::quiet_NaN());
	constexpr std::array<double, 6> a = {-3.969683028665376e+01, 2.209460984245205e+02,  -2.759285104469687e+02,
					     1.383577518672690e+02,  -3.066479806614716e+01, 2.506628277459239e+00};
	constexpr std::array<double, 5> b = {-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
					     6.680131188771972e+01, -1.328068155288572e+01};
	constexpr std::array<double, 6> c = {-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
					     -2.549732539343734e+00, 4.374664141464968e+00,  2.938163982698783e+00};
	constexpr std::array<double, 4> d = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
					     3.754408661907416e+00};
	constexpr double kLow = 0.02425;
	const auto tail = [&](double q) {
		return (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
		       ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
	};
	double x;
	if (p < kLow) {
		x = tail(std::sqrt(-2 * std::log(p)));
	} else if (p > 1 - kLow) {
		x = -tail(std::sqrt(-2 * std::log1p(-p)));
	} else {
		const double q = p - 0.5, r = q * q;
		x = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
		    (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1);
	}
	const double e = 0.5 * std::erfc(-x / std::numbers::sqrt2) - p;
	const double u = e * std::sqrt(2 * std::numbers::pi) * std::exp(x * x / 2);
	return x - u / (1 + x * u / 2);
}

double chi2_quantile(int dof, double p)
{
	// Wilson-Hilferty: chi2_k(p) ~ k (1 - 2/(9k) + z_p sqrt(2/(9k)))^3, within 1 % for k >= 1 at p >= 0.9.
	const double k = std::max(dof, 1);
	const double a = 2.0 / (9.0 * k);
	const double c = 1 - a + normal_quantile(p) * std::sqrt(a);
	return k * c * c * c;
}

MotionPrior MotionPrior::constant_velocity(const geometry::Pose &last_motion, double last_interval_s, double interval_s,
					   const EgoParams &params)
{
	MotionPrior prior;
	const double scale = last_interval_s > 0 && interval_s > 0 ? interval_s / last_interval_s : 1.0;
	prior.predicted.r = geometry::rotation_from_vector(geometry::vector_from_rotation(last_motion.r) * scale);
	prior.predicted.t = last_motion.t * scale;
	// A velocity change of a * dt moves the camera by up to a * dt^2 more (or less) than predicted.
	prior.translation_tolerance_m = params.max_acceleration_mps2 * interval_s * interval_s;
	prior.rotation_tolerance_rad = params.max_angular_acceleration_radps2 * interval_s * interval_s;
	return prior;
}

PoseEstimate estimate_pose(std::span<const cv::Vec3f> prev_xyz, std::span<const cv::Point2f> cur_px,
			   std::span<const uint8_t> votes, const geometry::StereoRig &rig, const EgoParams &params,
			   const MotionPrior *prior)
{
	PoseEstimate out;
	const size_t n = std::min(prev_xyz.size(), cur_px.size());
	out.inlier_mask.assign(n, 0);
	std::vector<cv::Point3f> object;
	std::vector<cv::Point2f> image;
	std::vector<size_t> index;
	for (size_t i = 0; i < n; ++i) {
		const cv::Vec3f &p = prev_xyz[i];
		if ((i < votes.size() && votes[i] == 0) || !std::isfinite(p[2]) || !(p[2] > 0) ||
		    p[2] > static_cast<float>(params.max_depth_m))
			continue;
		object.emplace_back(p[0], p[1], p[2]);
		image.push_back(cur_px[i]);
		index.push_back(i);
	}
	out.candidates = static_cast<int>(object.size());
	if (prior != nullptr && (prior->translation_tolerance_m > 0 || prior->rotation_tolerance_rad > 0)) {
		// Keep the points the predicted motion explains within what the tolerances allow at their depth:
		// a rotation error moves every point by about f * dr, a translation error by f * dt / z.
		std::vector<cv::Point3f> gated_object;
		std::vector<cv::Point2f> gated_image;
		std::vector<size_t> gated_index;
		for (size_t k = 0; k < object.size(); ++k) {
			const cv::Vec3d p(object[k].x, object[k].y, object[k].z);
			const auto predicted = rig.project(prior->predicted * p);
			if (!predicted)
				continue;
			const double allowed =
				params.ransac_threshold_px + rig.fx * prior->rotation_tolerance_rad +
				rig.fx * prior->translation_tolerance_m / std::max<double>(object[k].z, 0.1);
			if (std::hypot(predicted->x - image[k].x, predicted->y - image[k].y) <= allowed) {
				gated_object.push_back(object[k]);
				gated_image.push_back(image[k]);
				gated_index.push_back(index[k]);
			}
		}
		if (static_cast<int>(gated_object.size()) >= std::max(params.min_inliers, 6)) {
			object = std::move(gated_object);
			image = std::move(gated_image);
			index = std::move(gated_index);
			out.prior_used = true;
		}
	}
	if (static_cast<int>(object.size()) < std::max(params.min_inliers, 6)) {
		out.reason = "only " + std::to_string(out.candidates) + " static points with depth (need " +
			     std::to_string(std::max(params.min_inliers, 6)) + ")";
		return out;
	}
	// RANSAC over P3P hypotheses, each scored by its inliers; with a prior, a hypothesis the camera cannot
	// reach within the acceleration bounds is not considered at all. A fixed generator seed keeps a replay
	// giving the same poses.
	const auto plausible = [&](const geometry::Pose &pose) {
		if (prior == nullptr)
			return true;
		return cv::norm(pose.t - prior->predicted.t) <= prior->translation_tolerance_m + kPriorSlackM &&
		       (prior->predicted.inverse() * pose).angle() <= prior->rotation_tolerance_rad + kPriorSlackRad;
	};
	// Fitted at the footage's own noise: at the loose first distance the near static points that decide the
	// translation count as much when they are off by 1.5 px as when they fit, and a mover whose image barely
	// moves can pull the pose along the trade far points cannot see. The noise is the previous frame's when
	// the prior carries it (one fit), else measured from a first fit at the loose distance.
	const auto tight_for = [&](double sigma) {
		return std::clamp(params.ransac_threshold_sigmas * sigma, params.min_ransac_threshold_px,
				  params.ransac_threshold_px);
	};
	const auto enough = [&](const std::optional<PoseFit> &fit) {
		return fit && static_cast<int>(fit->inliers.size()) >= params.min_inliers;
	};
	std::optional<PoseFit> taken;
	double measured_sigma_px = -1; // the taken fit's noise once measured (negative: not yet)
	if (params.ransac_threshold_sigmas > 0 && prior != nullptr && prior->noise_px > 0) {
		taken = fit_pose(object, image, rig, params, tight_for(prior->noise_px), plausible);
		out.samples += taken ? taken->samples : 0;
		if (!enough(taken))
			taken.reset();
	}
	if (!taken) {
		const std::optional<PoseFit> first =
			fit_pose(object, image, rig, params, params.ransac_threshold_px, plausible);
		out.samples += first ? first->samples : 0;
		if (!enough(first)) {
			const size_t agree = first ? first->inliers.size() : 0;
			out.reason = "no consistent motion: " + std::to_string(agree) + " of " +
				     std::to_string(out.candidates) + " points agree" +
				     (prior != nullptr ? " within the acceleration bounds" : "");
			return out;
		}
		taken = first;
		measured_sigma_px = residual_sigma(object, image, rig, first->pose);
		const double tight_px = tight_for(measured_sigma_px);
		if (params.ransac_threshold_sigmas > 0 && tight_px < params.ransac_threshold_px) {
			std::optional<PoseFit> second = fit_pose(object, image, rig, params, tight_px, plausible);
			out.samples += second ? second->samples : 0;
			if (enough(second)) {
				taken = std::move(second);
				measured_sigma_px = -1;
			}
		}
	}
	out.curr_from_prev = taken->pose;
	out.threshold_px = taken->threshold_px;
	out.inliers = static_cast<int>(taken->inliers.size());
	out.rms_px = taken->rms_px;
	out.residual_sigma_px =
		measured_sigma_px >= 0 ? measured_sigma_px : residual_sigma(object, image, rig, taken->pose);
	for (int i : taken->inliers)
		out.inlier_mask[index[static_cast<size_t>(i)]] = 1;
	if (out.inliers < params.min_inliers || !std::isfinite(out.curr_from_prev.t[0]) ||
	    !std::isfinite(out.curr_from_prev.t[1]) || !std::isfinite(out.curr_from_prev.t[2])) {
		out.reason = "refinement left " + std::to_string(out.inliers) + " inliers";
		return out;
	}
	out.valid = true;
	return out;
}

double anchored_depth_drift(const cv::Vec3f &anchor_world, float anchor_sigma_m,
			    const geometry::Pose &camera_from_world, double cur_depth_m, double cur_sigma_m)
{
	if (!std::isfinite(anchor_world[0]) || !std::isfinite(cur_depth_m) || !(cur_depth_m > 0))
		return std::numeric_limits<double>::quiet_NaN();
	const cv::Vec3d seen = camera_from_world * cv::Vec3d(anchor_world[0], anchor_world[1], anchor_world[2]);
	if (!(seen[2] > 0))
		return std::numeric_limits<double>::quiet_NaN();
	const double var = static_cast<double>(anchor_sigma_m) * anchor_sigma_m + cur_sigma_m * cur_sigma_m;
	return var > 0 ? (seen[2] - cur_depth_m) / std::sqrt(var) : std::numeric_limits<double>::quiet_NaN();
}

double anchored_depth_statistic(const cv::Vec3f &anchor_world, float anchor_sigma_m,
				const geometry::Pose &camera_from_world, float cur_depth_m, double cur_sigma_m)
{
	const double drift =
		anchored_depth_drift(anchor_world, anchor_sigma_m, camera_from_world, cur_depth_m, cur_sigma_m);
	return drift * drift;
}

double measured_disparity_sigma(std::span<const cv::Vec3f> prev_xyz, std::span<const float> cur_depth_m,
				std::span<const uint8_t> inlier_mask, const geometry::Pose &curr_from_prev,
				const geometry::StereoRig &rig, size_t min_points)
{
	const double fb = rig.fx * rig.baseline_m;
	std::vector<double> differences;
	for (size_t i = 0; i < prev_xyz.size() && i < cur_depth_m.size() && i < inlier_mask.size(); ++i) {
		if (inlier_mask[i] == 0 || !std::isfinite(prev_xyz[i][2]) || !(cur_depth_m[i] > 0) ||
		    !std::isfinite(cur_depth_m[i]))
			continue;
		const double z_pred = (curr_from_prev * cv::Vec3d(prev_xyz[i][0], prev_xyz[i][1], prev_xyz[i][2]))[2];
		if (!(z_pred > 0))
			continue;
		differences.push_back(std::abs(fb / z_pred - fb / static_cast<double>(cur_depth_m[i])));
	}
	if (differences.size() < std::max<size_t>(min_points, 1) || !(fb > 0))
		return 0;
	const auto mid = differences.begin() + static_cast<std::ptrdiff_t>(differences.size() / 2);
	std::nth_element(differences.begin(), mid, differences.end());
	constexpr double kMadToSigma = 1 / 0.6744897501960817;
	return *mid * kMadToSigma / std::numbers::sqrt2;
}

bool continues_motion(cv::Point2f residual, cv::Point2f prev_residual, double residual_var_px2, double change,
		      double quantile)
{
	if (change <= 0 || !std::isfinite(prev_residual.x) || !std::isfinite(prev_residual.y) ||
	    !std::isfinite(residual.x) || !std::isfinite(residual.y))
		return true;
	const cv::Point2d r(residual), d = r - cv::Point2d(prev_residual);
	const double var = 2 * residual_var_px2 + change * change * r.dot(r);
	return d.dot(d) <= chi2_quantile(2, quantile) * var;
}

GeometricContext GeometricContext::make(const geometry::StereoRig &rig, const geometry::Pose &curr_from_prev,
					double disparity_sigma_px, const EgoParams &params, double residual_sigma_px)
{
	GeometricContext context;
	context.rig = rig;
	context.curr_from_prev = curr_from_prev;
	context.disparity_sigma_px = disparity_sigma_px;
	context.params = params;
	if (params.measured_noise && residual_sigma_px > 0) {
		const double sigma = std::max(residual_sigma_px, params.min_pixel_sigma_px);
		context.residual_var_px2 = sigma * sigma;
	} else {
		// A fixed noise per feature position: the residual carries it at both ends.
		context.residual_var_px2 = 2 * params.pixel_sigma_px * params.pixel_sigma_px;
	}
	// Below a millimetre of translation there are no usable epipolar lines: the camera only turned.
	context.fundamental = curr_from_prev.distance() > 1e-3
				      ? geometry::fundamental_from_pose(rig.k(), curr_from_prev)
				      : cv::Matx33d::zeros();
	return context;
}

GeometricTest geometric_test(const GeometricContext &context, cv::Point2f prev_px, const cv::Vec3f &prev_xyz,
			     cv::Point2f cur_px, float cur_depth_m)
{
	GeometricTest test;
	test.predicted = {kNaN, kNaN};
	const geometry::StereoRig &rig = context.rig;
	const geometry::Pose &pose = context.curr_from_prev;
	const EgoParams &params = context.params;
	const double var = context.residual_var_px2;
	const bool translated = cv::norm(context.fundamental) > 0;

	// Where the point would be at infinite depth: the rotation alone moves it.
	const cv::Vec3d ray = pose.r * cv::Vec3d((prev_px.x - rig.cx) / rig.fx, (prev_px.y - rig.cy) / rig.fy, 1);
	const auto at_infinity = rig.project(ray);
	const bool has_prev_depth = std::isfinite(prev_xyz[2]) && prev_xyz[2] > 0;
	const cv::Point2d cur(cur_px.x, cur_px.y);

	if (!has_prev_depth) {
		if (!translated && at_infinity) {
			// Only a turn: every static point lands where its ray does, whatever its depth.
			const cv::Point2d r = cur - *at_infinity;
			test.d1_px = std::hypot(r.x, r.y);
			test.statistic = r.dot(r) / var;
			test.dof = 2;
			test.predicted = cv::Point2f(*at_infinity);
		} else if (translated) {
			test.d1_px = geometry::epipolar_distance(context.fundamental, cv::Point2d(prev_px), cur);
			test.statistic = test.d1_px * test.d1_px / var;
			test.dof = 1;
		}
		test.moving = test.dof > 0 && test.statistic > chi2_quantile(test.dof, params.chi2_quantile);
		return test;
	}

	const cv::Vec3d moved = pose * cv::Vec3d(prev_xyz[0], prev_xyz[1], prev_xyz[2]);
	const auto predicted = rig.project(moved);
	if (!predicted || !at_infinity)
		return test; // the point went behind the camera: nothing to compare
	test.predicted = cv::Point2f(*predicted);
	const cv::Point2d r = cur - *predicted;
	if (!translated) {
		// Only a turn: no epipolar line to split the residual along, so it is tested whole; the depth is
		// still predicted (a point walking straight at a still camera changes only its depth).
		test.d1_px = std::hypot(r.x, r.y);
		test.statistic = r.dot(r) / var;
		test.dof = 2;
	} else {
		test.d1_px = geometry::epipolar_distance(context.fundamental, cv::Point2d(prev_px), cur);
		test.statistic = test.d1_px * test.d1_px / var;
		test.dof = 1;
	}
	if (translated && params.along_line) {
		test.along_px = std::sqrt(std::max(0.0, r.dot(r) - test.d1_px * test.d1_px));
		const double parallax = cv::norm(*predicted - *at_infinity);
		const double z_prev = prev_xyz[2];
		const double relative = rig.depth_sigma(z_prev, context.disparity_sigma_px) / z_prev;
		const double along_var = var + parallax * parallax * relative * relative;
		test.statistic += test.along_px * test.along_px / along_var;
		++test.dof;
	}
	if (params.depth_check && std::isfinite(cur_depth_m) && cur_depth_m > 0) {
		const double z_pred = moved[2];
		test.d2_m = z_pred - cur_depth_m;
		const double sp = rig.depth_sigma(z_pred, context.disparity_sigma_px);
		const double sm = rig.depth_sigma(cur_depth_m, context.disparity_sigma_px);
		test.statistic += test.d2_m * test.d2_m / (sp * sp + sm * sm);
		++test.dof;
	}
	test.moving = test.statistic > chi2_quantile(test.dof, params.chi2_quantile);
	return test;
}

AnchorRefinement refine_against_anchors(std::span<const AnchorView> anchors, const geometry::Pose &world_from_camera,
					const geometry::StereoRig &rig, const EgoParams &params)
{
	AnchorRefinement out;
	out.world_from_camera = world_from_camera;
	const geometry::Pose chained = world_from_camera.inverse(); // camera_from_world
	std::vector<cv::Point3f> object;
	std::vector<cv::Point2f> image;
	object.reserve(anchors.size());
	image.reserve(anchors.size());
	for (const AnchorView &anchor : anchors) {
		const cv::Vec3d world(anchor.world[0], anchor.world[1], anchor.world[2]);
		if (!std::isfinite(world[0]) || !std::isfinite(world[2]))
			continue;
		const cv::Vec3d p = chained * world;
		if (!(p[2] > 0))
			continue;
		object.emplace_back(anchor.world[0], anchor.world[1], anchor.world[2]);
		image.push_back(anchor.px);
	}
	out.points = static_cast<int>(object.size());
	double rms = 0;
	std::vector<int> inliers = inliers_of(object, image, rig, chained, params.ransac_threshold_px, rms);
	if (static_cast<int>(inliers.size()) < params.anchor_refine_min_points)
		return out;
	const std::vector<int> first = inliers;
	const geometry::Pose refined = refine_on_inliers(
		object, image, rig, chained, params.ransac_threshold_px, params.anchor_refine_min_points,
		[](const geometry::Pose &) { return true; }, inliers);
	// Compared over the chained pose's inliers, so a refinement cannot win by dropping points.
	const auto rms_over = [&](const geometry::Pose &pose) {
		double sum2 = 0;
		for (int i : first)
			sum2 += std::min(error2(object, image, static_cast<size_t>(i), rig, pose),
					 params.ransac_threshold_px * params.ransac_threshold_px);
		return std::sqrt(sum2 / static_cast<double>(first.size()));
	};
	out.rms_before_px = rms_over(chained);
	out.rms_after_px = rms_over(refined);
	out.inliers = static_cast<int>(inliers.size());
	const geometry::Pose correction = refined * world_from_camera; // identity when nothing changed
	const double turn_rad = cv::norm(geometry::vector_from_rotation(correction.r));
	constexpr double kMaxCorrectionM = 0.05, kMaxCorrectionRad = 1.0 * std::numbers::pi / 180;
	if (!(out.rms_after_px < out.rms_before_px) || !(cv::norm(correction.t) <= kMaxCorrectionM) ||
	    !(turn_rad <= kMaxCorrectionRad))
		return out;
	out.applied = true;
	// The step from the chained pose to the refined one, in this camera (refined = step * chained), and the
	// share of it applied.
	const geometry::Pose step = refined * chained.inverse();
	geometry::Pose part;
	part.r = geometry::rotation_from_vector(params.anchor_refine_gain * geometry::vector_from_rotation(step.r));
	part.t = params.anchor_refine_gain * step.t;
	out.world_from_camera = (part * chained).inverse();
	return out;
}

} // namespace stereod::vision
