// Sparse stereo accuracy on real data (not a test by itself): Middlebury 2006 "Aloe" (aloeL/aloeR and its
// ground-truth disparity aloeGT, in ../shared/data/opencv_samples or opencv-doc's examples), matched by
// core/vision/stereo.hpp, and OpenCV's semi-global matcher at the same points as the baseline of the same run.
// Prints a table; --max-median-px makes it exit 1 when the median error is above that (the data test).
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include <CLI/CLI.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/vision/stereo.hpp"

namespace fs = std::filesystem;
using namespace stereod;

namespace {

struct Row {
	std::string method;
	size_t points = 0;
	double median = 0, mean = 0, within_half = 0, within_one = 0;
};

Row score(const std::string &method, const std::vector<double> &errors)
{
	Row row{method, errors.size()};
	if (errors.empty())
		return row;
	std::vector<double> sorted = errors;
	std::sort(sorted.begin(), sorted.end());
	row.median = sorted[sorted.size() / 2];
	double sum = 0;
	for (double e : sorted) {
		sum += e;
		row.within_half += e <= 0.5 ? 1 : 0;
		row.within_one += e <= 1.0 ? 1 : 0;
	}
	row.mean = sum / static_cast<double>(sorted.size());
	row.within_half /= static_cast<double>(sorted.size());
	row.within_one /= static_cast<double>(sorted.size());
	return row;
}

} // namespace

int main(int argc, char **argv)
{
	CLI::App app("sparse stereo accuracy on Middlebury Aloe");
	std::string dir;
	double gt_scale = 1;
	double max_median = 0;
	std::string detector = "orb";
	app.add_option("--data", dir,
		       "folder with aloeL.jpg, aloeR.jpg, aloeGT.png (default: ../shared/data/opencv_samples, "
		       "then opencv-doc's examples)");
	app.add_option("--gt-scale", gt_scale, "ground truth value per pixel of disparity")->capture_default_str();
	app.add_option("--detector", detector, "orb | surf")->capture_default_str();
	app.add_option("--max-median-px", max_median, "exit 1 when the median error exceeds this (0: report only)");
	vision::StereoParams sp;
	app.add_flag("!--no-row-search", sp.row_search, "descriptor matches only (stereo.row_search = false)");
	app.add_flag("--right-features", sp.right_features,
		     "the right eye's keypoints and descriptors first, as seed 002 (stereo.right_features = true)");
	app.add_option("--row-search-min-ncc", sp.row_search_min_ncc, "stereo.row_search_min_ncc")
		->capture_default_str();
	app.add_option("--row-search-uniqueness", sp.row_search_uniqueness, "stereo.row_search_uniqueness")
		->capture_default_str();
	app.add_option("--edge-split-px", sp.edge_split_px, "stereo.edge_split_px")->capture_default_str();
	app.add_flag("--drop-edge-depth", sp.drop_edge_depth,
		     "no depth for matches across a depth edge (stereo.drop_edge_depth); otherwise a row of them");
	CLI11_PARSE(app, argc, argv);
	if (!sp.row_search)
		sp.right_features = true; // descriptor matches are then all there is
	if (dir.empty()) {
		for (const char *candidate : {"../shared/data/opencv_samples", "../../shared/data/opencv_samples",
					      "/usr/share/doc/opencv-doc/examples/data"})
			if (fs::exists(fs::path(candidate) / "aloeGT.png")) {
				dir = candidate;
				break;
			}
	}
	const cv::Mat left = cv::imread((fs::path(dir) / "aloeL.jpg").string(), cv::IMREAD_COLOR);
	const cv::Mat right = cv::imread((fs::path(dir) / "aloeR.jpg").string(), cv::IMREAD_COLOR);
	const cv::Mat truth = cv::imread((fs::path(dir) / "aloeGT.png").string(), cv::IMREAD_GRAYSCALE);
	if (left.empty() || right.empty() || truth.empty()) {
		std::cerr << "SKIP: no aloeL.jpg/aloeR.jpg/aloeGT.png in '" << dir
			  << "' (../shared/data or opencv-doc: bash scripts/install-deps.sh)\n";
		return 77;
	}
	cv::Mat left_grey, right_grey;
	cv::cvtColor(left, left_grey, cv::COLOR_BGR2GRAY);
	cv::cvtColor(right, right_grey, cv::COLOR_BGR2GRAY);

	vision::FeatureParams fp;
	fp.detector = detector == "surf" ? vision::Detector::Surf : vision::Detector::Orb;
	fp.max_features = 2000;
	const vision::FrameFeatures lf = vision::extract_features(left, fp, 1, &left_grey);
	const vision::FrameFeatures rf =
		sp.right_features ? vision::extract_features(right, fp, 1, &right_grey) : vision::FrameFeatures{};
	sp.max_disparity_px = 300; // Aloe at full size reaches about 270 px
	// Any rig: the disparity is what is scored.
	const geometry::StereoRig rig{1000, 1000, left.cols / 2.0, left.rows / 2.0, 0.1};
	const double step = fp.detector == vision::Detector::Orb ? fp.orb_scale : 1.4;
	// The matching's cost with and without the row search, best of 20 (the machine is shared).
	const auto time_matching = [&](const vision::StereoParams &params) {
		double best = 1e9;
		for (int k = 0; k < 20; ++k) {
			const auto start = std::chrono::steady_clock::now();
			(void)vision::match_stereo(lf, rf, left_grey, right_grey, rig, params, step);
			best = std::min(best, std::chrono::duration<double, std::milli>(
						      std::chrono::steady_clock::now() - start)
						      .count());
		}
		return best;
	};
	vision::StereoParams descriptors_only = sp;
	descriptors_only.row_search = false;
	const double ms_descriptors = time_matching(descriptors_only);
	const double ms_configured = time_matching(sp);
	const vision::StereoDepth depth = vision::match_stereo(lf, rf, left_grey, right_grey, rig, sp, step);

	// Baseline: OpenCV's semi-global block matcher, dense, read at the same keypoints.
	auto sgbm = cv::StereoSGBM::create(0, 272, 5, 8 * 25, 32 * 25, 1, 0, 10, 100, 2, cv::StereoSGBM::MODE_SGBM);
	cv::Mat dense;
	sgbm->compute(left_grey, right_grey, dense); // CV_16S, 4 fractional bits

	std::vector<double> ours, theirs, raw, searched, clear, across;
	size_t no_truth = 0;
	for (size_t i = 0; i < lf.keypoints.size(); ++i) {
		if (std::isnan(depth.disparity[i]))
			continue;
		const cv::Point p(static_cast<int>(std::lround(lf.keypoints[i].pt.x)),
				  static_cast<int>(std::lround(lf.keypoints[i].pt.y)));
		const uint8_t g = truth.at<uint8_t>(p);
		if (g == 0) { // occluded or unknown in the ground truth
			++no_truth;
			continue;
		}
		const double true_d = g / gt_scale;
		ours.push_back(std::abs(depth.disparity[i] - true_d));
		(depth.on_edge[i] != 0 ? across : clear).push_back(ours.back());
		const int r = depth.right_index[i];
		if (r >= 0)
			raw.push_back(
				std::abs(lf.keypoints[i].pt.x - rf.keypoints[static_cast<size_t>(r)].pt.x - true_d));
		else // found along the row (search_row), no right keypoint
			searched.push_back(ours.back());
		const short s = dense.at<short>(p);
		if (s > 0)
			theirs.push_back(std::abs(s / 16.0 - true_d));
	}
	std::printf("Aloe %dx%d, %s, %zu left keypoints, %d matched (%d of them along the row, no right keypoint; %zu "
		    "without ground truth), ground truth / %.0f\n\n",
		    left.cols, left.rows, detector.c_str(), lf.keypoints.size(), depth.matched, depth.row_searched,
		    no_truth, gt_scale);
	std::printf("| method | points | median abs error px | mean px | <= 0.5 px | <= 1 px "
		    "|\n|---|---|---|---|---|---|\n");
	for (const Row &row : {score("stereod sparse (refined)", ours), score("stereod sparse, keypoint x only", raw),
			       score("stereod sparse, of them found along the row", searched),
			       score("stereod sparse, of them not across a depth edge", clear),
			       score("stereod sparse, of them across a depth edge (stereo.edge_split_px)", across),
			       score("OpenCV StereoSGBM at the same points", theirs)})
		std::printf("| %s | %zu | %.3f | %.3f | %.1f%% | %.1f%% |\n", row.method.c_str(), row.points,
			    row.median, row.mean, 100 * row.within_half, 100 * row.within_one);
	if (rf.keypoints.empty()) // the row search alone: no descriptor matching to time beside it
		std::printf("\nmatching time (best of 20): the row search alone %.2f ms\n", ms_configured);
	else
		std::printf("\nmatching time (best of 20): descriptors only %.2f ms, as configured %.2f ms\n",
			    ms_descriptors, ms_configured);
	const Row result = score("", ours);
	if (max_median > 0 && (result.points < 100 || result.median > max_median)) {
		std::fprintf(stderr,
			     "FAIL: median error %.3f px over %zu points (limit %.3f px, at least 100 points)\n",
			     result.median, result.points, max_median);
		return 1;
	}
	return 0;
}
