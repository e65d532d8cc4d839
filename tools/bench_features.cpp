// Benchmark (not a test): detect + describe time on a 1024x768 real image at the same feature count for
// this project's SURF (and its variants) against OpenCV SIFT, with OpenCV ORB and our bucketed ORB path for
// reference, all measured in this run. Also times the classification step alone on ~1000 matches.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <optional>

#include <CLI/CLI.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/vision/classifier.hpp"
#include "core/vision/features.hpp"
#include "core/vision/matching.hpp"
#include "core/vision/surf.hpp"
#include "core/vision/temporal.hpp"

using namespace stereod;
using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

namespace {

struct Timing {
	double median_ms = 0;
	double best_ms = 0;
	size_t features = 0;
};

Timing measure(int repeats, const std::function<size_t()> &run)
{
	std::vector<double> ms;
	size_t features = 0;
	for (int i = 0; i < repeats; ++i) {
		const auto start = Clock::now();
		features = run();
		ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - start).count());
	}
	std::sort(ms.begin(), ms.end());
	return {ms[ms.size() / 2], ms.front(), features};
}

} // namespace

int main(int argc, char **argv)
{
	CLI::App app{"feature extraction speed: our SURF vs OpenCV SIFT (and ORB) at 1024x768"};
	std::string image_path = "../shared/data/opencv_samples/aloeL.jpg";
	int n = 1000, repeats = 15, threads = 0;
	app.add_option("--image", image_path, "a real photograph; resized to 1024x768");
	app.add_option("-n,--features", n, "feature budget for every detector");
	app.add_option("-r,--repeats", repeats);
	app.add_option("--threads", threads, "OpenCV threads (0 = all cores), the same for every row");
	CLI11_PARSE(app, argc, argv);
	if (!fs::exists(image_path))
		image_path = "/usr/share/doc/opencv-doc/examples/data/aloeL.jpg";
	cv::Mat colour = cv::imread(image_path, cv::IMREAD_COLOR);
	if (colour.empty()) {
		std::fprintf(stderr, "cannot read %s\n", image_path.c_str());
		return 2;
	}
	cv::resize(colour, colour, cv::Size(1024, 768), 0, 0, cv::INTER_AREA);
	cv::Mat grey;
	cv::cvtColor(colour, grey, cv::COLOR_BGR2GRAY);
	if (threads > 0)
		cv::setNumThreads(threads);
	std::printf("image %s resized to 1024x768, budget %d features, median of %d runs, %d OpenCV threads\n\n",
		    image_path.c_str(), n, repeats, cv::getNumThreads());

	auto surf = [&](bool upright, bool extended) {
		return [&, upright, extended] {
			vision::SurfParams p;
			p.max_features = n;
			p.upright = upright;
			p.extended = extended;
			const cv::Mat ii = vision::surf_integral(grey);
			auto kps = vision::surf_detect(ii, p);
			const cv::Mat d = vision::surf_describe(ii, kps, p);
			return static_cast<size_t>(d.rows);
		};
	};
	auto opencv = [&](cv::Ptr<cv::Feature2D> detector) {
		return [&grey, detector] {
			std::vector<cv::KeyPoint> kps;
			cv::Mat d;
			detector->detectAndCompute(grey, cv::noArray(), kps, d);
			return static_cast<size_t>(d.rows);
		};
	};
	// first_pass: ORB's first FAST threshold where not the default (0: one pass, the same keypoints)
	auto bucketed_orb = [&](vision::CandidateSelection selection, std::optional<int> first_pass = std::nullopt) {
		return [&colour, n, selection, first_pass] {
			vision::FeatureParams p;
			p.max_features = n;
			p.candidate_selection = selection;
			if (first_pass)
				p.orb_fast_first_pass_threshold = *first_pass;
			return vision::extract_features(colour, p, 1).keypoints.size();
		};
	};
	const Timing sift = measure(repeats, opencv(cv::SIFT::create(n)));
	std::vector<std::pair<std::string, Timing>> rows = {
		{"SIFT (OpenCV) - baseline", sift},
		{"SURF (ours, 64-d)", measure(repeats, surf(false, false))},
		{"SURF (ours, 128-d extended)", measure(repeats, surf(false, true))},
		{"U-SURF (ours, upright 64-d)", measure(repeats, surf(true, false))},
		{"ORB (OpenCV, 8 levels)", measure(repeats, opencv(cv::ORB::create(n)))},
		{"ORB bucketed (our ORB path, candidates per cell: the default)",
		 measure(repeats, bucketed_orb(vision::CandidateSelection::PerCell))},
		{"ORB bucketed (candidates per cell, FAST in one pass: the same keypoints)",
		 measure(repeats, bucketed_orb(vision::CandidateSelection::PerCell, 0))},
		{"ORB bucketed (our ORB path, candidates over the whole image)",
		 measure(repeats, bucketed_orb(vision::CandidateSelection::WholeImage))},
	};
	std::printf("| detector + descriptor | features | median ms | best ms | speed-up vs SIFT (median) |\n"
		    "|---|---|---|---|---|\n");
	for (const auto &[name, t] : rows)
		std::printf("| %s | %zu | %.1f | %.1f | %.1fx |\n", name.c_str(), t.features, t.median_ms, t.best_ms,
			    sift.median_ms / t.median_ms);

	// The classification step alone (everything after matching), on the matches of two real frames: the
	// image and a slightly rotated, shifted copy with a patch moved, so all branches run.
	cv::Mat next;
	const cv::Mat rotation = cv::getRotationMatrix2D(cv::Point2f(512, 384), 1.0, 1.0);
	cv::warpAffine(colour, next, rotation, colour.size());
	colour(cv::Rect(100, 100, 200, 300)).copyTo(next(cv::Rect(130, 105, 200, 300)));
	vision::FeatureParams fp;
	fp.max_features = 1500;
	const auto f0 = vision::extract_features(colour, fp, 1), f1 = vision::extract_features(next, fp, 1);
	const auto matches = vision::match_features(f0, f1, vision::MatchParams{});
	std::vector<vision::PointPair> pairs;
	for (const auto &m : matches)
		pairs.push_back({f0.keypoints[static_cast<size_t>(m.prev)].pt,
				 f1.keypoints[static_cast<size_t>(m.cur)].pt, f0.colours[static_cast<size_t>(m.prev)],
				 f1.colours[static_cast<size_t>(m.cur)]});
	const Timing match_t =
		measure(repeats, [&] { return vision::match_features(f0, f1, vision::MatchParams{}).size(); });
	// Guided matching with the scene's motion as the prediction (what the pipeline has from the frame before).
	std::vector<cv::Point2f> predicted;
	for (const auto &k : f0.keypoints) {
		const cv::Matx23d r(rotation);
		predicted.emplace_back(static_cast<float>(r(0, 0) * k.pt.x + r(0, 1) * k.pt.y + r(0, 2)),
				       static_cast<float>(r(1, 0) * k.pt.x + r(1, 1) * k.pt.y + r(1, 2)));
	}
	const Timing guided_t = measure(repeats, [&] {
		return vision::match_features_guided(f0, f1, predicted, vision::MatchParams{}).size();
	});
	const size_t guided_count = vision::match_features_guided(f0, f1, predicted, vision::MatchParams{}).size();
	const Timing classify_t = measure(
		repeats * 4, [&] { return vision::classify(pairs, next, vision::ClassifierParams{}).labels.size(); });
	// The same plus the motion memory (temporal.hpp), which follows every match from a previous memory.
	vision::TrackSet previous_memory;
	previous_memory.by_keypoint.resize(f0.keypoints.size());
	for (auto &state : previous_memory.by_keypoint) {
		state.id = previous_memory.next_id++;
		state.age = 5;
		state.count = 4;
		state.noise_weight = 3;
	}
	previous_memory.t_ns = 0;
	const Timing memory_t = measure(repeats * 4, [&] {
		const vision::ClassifierParams cp;
		const vision::TemporalParams tp;
		auto classification = vision::classify(pairs, next, cp);
		vision::FollowInput follow;
		follow.matches = matches;
		follow.pairs = pairs;
		follow.homography = classification.homography ? &*classification.homography : nullptr;
		follow.texture_agrees = classification.texture_agrees;
		follow.cur_keypoints = f1.keypoints.size();
		follow.t_ns = 33'333'333;
		const vision::TrackSet memory = vision::follow_tracks(&previous_memory, follow, cp, tp);
		return static_cast<size_t>(
			vision::promote_remembered_movers(classification.labels, matches, memory, cp, tp));
	});
	std::printf("\n| step | input | median ms | best ms |\n|---|---|---|---|\n");
	std::printf("| matching (one-pass brute force, ratio + cross check) | %zu x %zu ORB | %.2f | %.2f |\n",
		    f0.keypoints.size(), f1.keypoints.size(), match_t.median_ms, match_t.best_ms);
	std::printf(
		"| matching guided (64 px around the prediction; %zu vs %zu matches) | %zu x %zu ORB | %.2f | %.2f |\n",
		guided_count, matches.size(), f0.keypoints.size(), f1.keypoints.size(), guided_t.median_ms,
		guided_t.best_ms);
	std::printf("| classification (seed 000, all steps after matching) | %zu matches | %.2f | %.2f |\n",
		    pairs.size(), classify_t.median_ms, classify_t.best_ms);
	std::printf("| classification + motion memory (all after matching, as the pipeline runs it) | %zu matches | "
		    "%.2f | %.2f |\n",
		    pairs.size(), memory_t.median_ms, memory_t.best_ms);
	return 0;
}
