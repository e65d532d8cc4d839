#pragma once
// Detector repeatability and descriptor matching score under a known homography, following Mikolajczyk
// et al., "A comparison of affine region detectors" (IJCV 2005): each keypoint is a circular region
// (radius = KeyPoint::size / 2); image 1's region is mapped into image 2 by the homography's local affine
// approximation; both are normalised so the mapped region of image 1 has radius 30 px; a pair corresponds
// when the overlap error 1 - |A n B| / |A u B| is below 40%. Only keypoints visible in both images count.
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace stereod::tools {

struct Features {
	std::vector<cv::KeyPoint> keypoints;
	cv::Mat descriptors;
	int norm = 0; ///< cv::NORM_L2 or cv::NORM_HAMMING
};

struct QualityScore {
	size_t keypoints_1 = 0; ///< in the part of image 1 that image 2 also sees
	size_t keypoints_2 = 0;
	size_t correspondences = 0; ///< one-to-one region correspondences (overlap error < 40%)
	size_t correct_matches = 0; ///< nearest-neighbour descriptor matches that are correspondences
	[[nodiscard]] double repeatability() const;
	[[nodiscard]] double matching_score() const;
};

/// Overlap error of two ellipses x'M x <= 1 centred at c1 and c2, by sampling a grid over both.
double ellipse_overlap_error(const cv::Matx22d &m1, cv::Point2d c1, const cv::Matx22d &m2, cv::Point2d c2);

QualityScore evaluate_quality(const Features &f1, cv::Size size1, const Features &f2, cv::Size size2,
			      const cv::Matx33d &h_1to2, double max_overlap_error = 0.4);

} // namespace stereod::tools
