#pragma once
// SURF (Bay, Ess, Tuytelaars, Van Gool, "Speeded-Up Robust Features", CVIU 2008), implemented here because
// Debian's OpenCV does not ship the non-free module.
//
//   detector    fast-Hessian: box-filter approximations of the Hessian on an integral image, filter sizes
//               9, 15, 21, 27 in the first octave (doubling steps after), sampling step doubled per octave,
//               3x3x3 non-maximum suppression and sub-pixel/sub-scale interpolation by a quadratic fit
//   orientation Haar wavelet responses (size 4s) in a radius of 6s, Gaussian-weighted (2s), the largest sum
//               in a sliding pi/3 window
//   descriptor  a 20s square oriented region, 4x4 subregions of 5x5 samples of Haar responses (size 2s),
//               Gaussian-weighted (3.3s): sum dx, sum dy, sum |dx|, sum |dy| per subregion -> 64-d, unit
//               length; `extended` splits the sums by the sign of the other response -> 128-d; `upright`
//               skips the orientation (U-SURF)
#include <vector>

#include <opencv2/core.hpp>

namespace stereod::vision {

struct SurfParams {
	double hessian_threshold = 10.0; ///< on det(H) of box-filter responses of 8-bit intensities
	int octaves = 4;
	int initial_step = 2; ///< sampling step of the first octave (1 = every pixel, slower)
	int max_features = 0; ///< keep the strongest this many after detection; 0 = all
	bool extended = false;
	bool upright = false;
};

/// One detected interest point: position, scale (sigma), orientation, response and sign of the Laplacian.
struct SurfKeypoint {
	cv::Point2f pt;
	float scale = 0;       ///< sigma = 1.2 * filter size / 9
	float orientation = 0; ///< radians
	float response = 0;
	int laplacian = 0; ///< +1 or -1: bright blob on dark or dark on bright (matching can require equality)
	[[nodiscard]] cv::KeyPoint to_cv() const;
};

/// Integral image of a grey 8-bit image, CV_32S with one extra row and column (OpenCV's convention).
cv::Mat surf_integral(const cv::Mat &grey);

std::vector<SurfKeypoint> surf_detect(const cv::Mat &integral, const SurfParams &params);
/// Assigns orientations (unless upright) and computes descriptors, one CV_32F row per keypoint.
cv::Mat surf_describe(const cv::Mat &integral, std::vector<SurfKeypoint> &keypoints, const SurfParams &params);

} // namespace stereod::vision
