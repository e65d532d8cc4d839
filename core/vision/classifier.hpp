#pragma once
// Static/dynamic classification of matched feature points by the second re-projection error with area and
// RGB texture constraints (seed 000: ../shared/seeds/000_*.txt, equations 1-7, Tables 1-3).
//
// Each step is its own pure function so it can be tested on constructed data; classify() chains them:
//   1. initial homography by RANSAC over all matches                          (Table 1)
//   2. re-projection error, eq. 1, against a Mahalanobis threshold -> initial static / uncertain
//   3. static area constraint, eq. 5, adaptive window theta*Umax, eta*Vmax   (Table 2)
//   4. static texture constraint, eqs. 2-4: d_n < T                          (Table 2)
//   5. homography re-estimated from the refined static set
//   6. second re-projection of the uncertain points with that homography
//   7. dynamic area constraint, eq. 5 with the dynamic coefficients          (Table 3)
//   8. double texture constraint, eqs. 6-7: d_n < T and dd_n > T -> dynamic  (Table 3)
// Points rejected by a constraint are the seed's mismatches; they are labelled Uncertain.
#include <optional>
#include <span>
#include <vector>

#include <opencv2/core.hpp>

#include "core/result.hpp"

namespace stereod::vision {

struct ClassifierParams {
	double ransac_threshold_px = 3.0;   ///< RANSAC inlier distance for both homography fits
	double reprojection_sigma_px = 1.0; ///< feature position noise (isotropic Gaussian) for eq. 1
	/// Gate on eq. 1 over sigma^2. Eq. 1 (the geometric re-projection error of a homography, codimension 2)
	/// is sigma^2 chi-square with 2 degrees of freedom for a point the homography explains: 9.21 is its 99%.
	double reprojection_chi2 = 9.21;
	double static_theta = 0.9;  ///< eq. 5 static window: du^2 < theta * Umax
	double static_eta = 0.9;    ///< eq. 5 static window: dv^2 < eta * Vmax
	double dynamic_theta = 1.0; ///< eq. 5 on the dynamic candidates' motion relative to the scene
	double dynamic_eta = 1.0;
	double area_floor_px = 2.0;	      ///< windows never shrink below this many pixels (still camera)
	double dynamic_max_motion_px = 150.0; ///< a mover cannot move farther than this between frames
	double alpha = 0.299;		      ///< eq. 3 weight of R
	double beta = 0.587;		      ///< eq. 3 weight of G
	double gamma = 0.114;		      ///< eq. 3 weight of B (alpha + beta + gamma = 1, eq. 4)
	double texture_threshold = 12.0;      ///< T, in 8-bit intensity units
	int texture_tolerance_px = 1;	      ///< eq. 3 takes the best match within this many pixels of the point
	int colour_radius = 1;		      ///< patch radius for colours sampled at projected points
	int min_matches = 12;		      ///< fewer matches: no homography, everything Uncertain
};

/// One match between frame n-1 and frame n, with the colours under both ends.
struct PointPair {
	cv::Point2f prev;
	cv::Point2f cur;
	cv::Vec3f prev_colour; ///< B,G,R
	cv::Vec3f cur_colour;
};

struct HomographyFit {
	cv::Matx33d h;
	std::vector<bool> inliers;
	int inlier_count = 0;
};

/// RANSAC homography from `from` to `to`; nothing when there are too few points or no consistent model.
std::optional<HomographyFit> fit_homography(std::span<const cv::Point2f> from, std::span<const cv::Point2f> to,
					    double ransac_threshold_px, int min_points);

cv::Point2f project(const cv::Matx33d &h, cv::Point2f p);

/// Eq. 1 as the seed writes it: d(x, x^)^2 + d(x', x^')^2, the squared distances from the measured points to
/// the closest pair (x^, x^' = H x^) the homography allows, in squared pixels. Computed to first order (the
/// Sampson error, Hartley & Zisserman 4.2.6): with r = x' - H(x) and A = dH(x)/dx, r^T (A A^T + I)^-1 r.
/// For H near the identity that is |r|^2 / 2: half the one-way transfer error, a quarter of the symmetric one.
double reprojection_error(const cv::Matx33d &h, cv::Point2f prev, cv::Point2f cur);

/// Eq. 1 against the Mahalanobis gate: true for a static candidate.
bool passes_reprojection(double error_px2, const ClassifierParams &params);

/// The adaptive window of eq. 5: the largest squared displacement along u and v, scaled.
struct AreaWindow {
	double max_du2 = 0;
	double max_dv2 = 0;
	double theta = 1;
	double eta = 1;
	double floor_px2 = 0;
	[[nodiscard]] bool contains(cv::Point2f displacement) const;
};
AreaWindow area_window(std::span<const cv::Point2f> displacements, double theta, double eta, double floor_px);

/// Eq. 3: alpha|dR| + beta|dG| + gamma|dB| between two B,G,R colours.
double texture_distance(const cv::Vec3f &a, const cv::Vec3f &b, const ClassifierParams &params);

/// Eq. 3 between a colour and the image around `at`, the smallest over positions within
/// texture_tolerance_px: keypoints are located to about a pixel, and at a corner (where detectors put them)
/// a one-pixel shift changes the colour by tens of levels, which would fail a static point.
double texture_distance_near(const cv::Vec3f &colour, const cv::Mat &image, cv::Point2f at,
			     const ClassifierParams &params);

struct ClassificationCounts {
	int matches = 0;
	int initial_static = 0;
	int initial_uncertain = 0;
	int static_after_area = 0;
	int static_after_texture = 0;
	int second_static = 0; ///< uncertain points the refined homography explains (and texture agrees)
	int dynamic_candidates = 0;
	int dynamic_after_area = 0;
	int dynamic = 0;
};

struct Classification {
	std::vector<PointLabel> labels;	       ///< one per input pair
	std::optional<cv::Matx33d> homography; ///< the refined frame-to-frame homography (step 5)
	/// False when step 5's fit failed (too few refined static points) and `homography` is step 1's.
	bool homography_refined = false;
	/// True when the points the motion memory calls moving left too few to fit step 1, so it was fitted
	/// over every match instead (the memory is then not trusted for this frame's fits).
	bool fitted_with_known_movers = false;
	std::vector<uint8_t> texture_agrees; ///< per pair: eq. 3 (within the tolerance) < T; empty without a homography
	int homography_inliers = 0;
	ClassificationCounts counts;
};

/// The whole chain. `cur_image` is frame n (BGR or grey), sampled at projected points for eq. 6.
/// `known_moving` (empty, or one per pair) marks points already known to move (the motion memory of
/// temporal.hpp): they take no part in either homography fit, so a slow mover cannot drag the static scene's
/// motion along with it; their labels are still decided by the steps above.
Classification classify(std::span<const PointPair> pairs, const cv::Mat &cur_image, const ClassifierParams &params,
			std::span<const uint8_t> known_moving = {});

} // namespace stereod::vision
