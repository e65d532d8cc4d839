// stereoctl calibrate: a stereo calibration from chessboard pairs, written as OpenCV YAML/XML for
// `calibration.file`.
//   stereoctl calibrate DIR -o stereo.yml [--board 9x6] [--square-mm 25]
// DIR holds leftNN.* / rightNN.* pairs (OpenCV's samples: left01.jpg, right01.jpg, ...) or left/ and right/
// folders with the same file names (the `folder` source's layout, e.g. `stereoctl export` output).
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <map>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/geometry/calibrate.hpp"
#include "drivers/calibration_file.hpp"
#include "tools/subcommands.hpp"

namespace stereod::tools {
namespace {

namespace fs = std::filesystem;

bool is_image(const fs::path &p)
{
	std::string ext = p.extension().string();
	std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return std::tolower(ch); });
	return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".bmp" || ext == ".pgm" || ext == ".ppm" ||
	       ext == ".tif" || ext == ".tiff";
}

/// (left, right) image paths in name order: leftX/rightX beside each other, or left/X and right/X.
std::vector<std::pair<fs::path, fs::path>> find_pairs(const fs::path &dir)
{
	std::map<std::string, std::pair<fs::path, fs::path>> by_key;
	auto collect = [&](const fs::path &folder, const std::string &prefix, bool left) {
		for (const auto &entry : fs::directory_iterator(folder)) {
			const std::string name = entry.path().filename().string();
			if (!entry.is_regular_file() || !is_image(entry.path()) || name.rfind(prefix, 0) != 0)
				continue;
			auto &slot = by_key[name.substr(prefix.size())];
			(left ? slot.first : slot.second) = entry.path();
		}
	};
	if (fs::is_directory(dir / "left") && fs::is_directory(dir / "right")) {
		collect(dir / "left", "", true);
		collect(dir / "right", "", false);
	} else {
		collect(dir, "left", true);
		collect(dir, "right", false);
	}
	std::vector<std::pair<fs::path, fs::path>> pairs;
	for (const auto &[key, pair] : by_key) {
		if (pair.first.empty() || pair.second.empty())
			std::cerr << "stereoctl calibrate: " << (pair.first.empty() ? pair.second : pair.first).string()
				  << " has no partner; skipped\n";
		else
			pairs.push_back(pair);
	}
	return pairs;
}

struct Options {
	std::string dir, output, board = "9x6";
	double square_mm = 25;
	bool json = false;
};

int calibrate(const Options &options)
{
	geometry::Chessboard board;
	if (std::sscanf(options.board.c_str(), "%dx%d", &board.inner_corners.width, &board.inner_corners.height) != 2 ||
	    board.inner_corners.width < 2 || board.inner_corners.height < 2)
		throw CLI::ValidationError("--board", "expected inner corners as WxH, e.g. 9x6");
	board.square_m = options.square_mm / 1000.0;
	const auto pairs = find_pairs(options.dir);
	if (pairs.empty())
		throw std::runtime_error(options.dir + ": no leftNN/rightNN image pairs and no left/, right/ folders");

	std::vector<std::vector<cv::Point2f>> left, right;
	std::vector<std::string> used;
	cv::Size size;
	nlohmann::json rejected = nlohmann::json::array();
	for (const auto &[l, r] : pairs) {
		const cv::Mat left_image = cv::imread(l.string(), cv::IMREAD_GRAYSCALE);
		const cv::Mat right_image = cv::imread(r.string(), cv::IMREAD_GRAYSCALE);
		std::string why;
		if (left_image.empty() || right_image.empty())
			why = "cannot be read";
		else if (left_image.size() != right_image.size())
			why = "the two images differ in size";
		else if (size.area() > 0 && left_image.size() != size)
			why = fmt::format("{}x{}, the first pair was {}x{}", left_image.cols, left_image.rows,
					  size.width, size.height);
		std::optional<std::vector<cv::Point2f>> found_left, found_right;
		if (why.empty()) {
			found_left = geometry::find_chessboard(left_image, board);
			found_right = geometry::find_chessboard(right_image, board);
			if (!found_left || !found_right)
				why = fmt::format("board {} not found in the {} image", options.board,
						  !found_left ? "left" : "right");
		}
		if (!why.empty()) {
			rejected.push_back({{"left", l.filename().string()}, {"why", why}});
			if (!options.json)
				std::cout << fmt::format("  {:<14} rejected: {}\n", l.filename().string(), why);
			continue;
		}
		size = left_image.size();
		left.push_back(std::move(*found_left));
		right.push_back(std::move(*found_right));
		used.push_back(l.filename().string());
	}
	if (left.size() < 3)
		throw std::runtime_error(fmt::format("{}: the board was found in both eyes of only {} pairs (3 needed)",
						     options.dir, left.size()));
	const geometry::PairCalibrationResult result = geometry::calibrate_pair(left, right, board, size);
	const auto problems = geometry::calibration_problems(result.calibration, size);
	drivers::write_calibration(options.output, result.calibration, size,
				   {result.rms_px, result.left_rms_px, result.right_rms_px,
				    static_cast<int>(left.size()), board.square_m});
	// Read back what was written: the file the daemon will load, rectified the way it will be.
	const geometry::PairCalibration written = drivers::read_calibration(options.output);
	const geometry::Rectification rectification = geometry::make_rectification(written, size);
	if (options.json) {
		nlohmann::json pairs_json = nlohmann::json::array();
		for (size_t i = 0; i < used.size(); ++i)
			pairs_json.push_back({{"left", used[i]}, {"rms_px", result.pair_rms_px[i]}});
		std::cout << nlohmann::json{{"output", options.output},
					    {"image_size", {size.width, size.height}},
					    {"pairs", pairs_json},
					    {"rejected", rejected},
					    {"rms_px", result.rms_px},
					    {"left_rms_px", result.left_rms_px},
					    {"right_rms_px", result.right_rms_px},
					    {"baseline_m", cv::norm(result.calibration.t)},
					    {"rectified",
					     {{"fx", rectification.rig.fx},
					      {"baseline_m", rectification.rig.baseline_m}}},
					    {"problems", problems}}
				     .dump()
			  << "\n";
	} else {
		for (size_t i = 0; i < used.size(); ++i)
			std::cout << fmt::format("  {:<14} rms {:.3f} px\n", used[i], result.pair_rms_px[i]);
		std::cout << fmt::format(
			"{} pairs of {}x{}: RMS re-projection error {:.3f} px (left alone {:.3f}, right "
			"alone {:.3f}); baseline {:.4f} m with {:.1f} mm squares; rectified f {:.1f} px\n",
			used.size(), size.width, size.height, result.rms_px, result.left_rms_px, result.right_rms_px,
			cv::norm(result.calibration.t), options.square_mm, rectification.rig.fx);
		for (const auto &problem : problems)
			std::cout << "problem: " << problem << "\n";
		std::cout << "written to " << options.output << " (use it as calibration.file)\n";
	}
	return problems.empty() ? 0 : 1;
}

} // namespace

void add_calibrate_command(CLI::App &app)
{
	auto *cmd = app.add_subcommand("calibrate",
				       "stereo calibration from chessboard pairs, written for calibration.file");
	auto options = std::make_shared<Options>();
	cmd->add_option("dir", options->dir, "leftNN/rightNN images, or left/ and right/ folders")
		->required()
		->check(CLI::ExistingDirectory);
	cmd->add_option("-o,--output", options->output, "calibration to write (.yml, .xml or .json)")->required();
	cmd->add_option("--board", options->board, "inner corners across x down")->capture_default_str();
	cmd->add_option("--square-mm", options->square_mm, "side of one square (the unit of the baseline)")
		->capture_default_str()
		->check(CLI::PositiveNumber);
	cmd->add_flag("--json", options->json, "one JSON object instead of the table");
	cmd->callback([options] { throw CLI::RuntimeError(calibrate(*options)); });
}

} // namespace stereod::tools
