// stereoctl export: a recording's frames as image files other tools read, pixel for pixel.
//   --layout pairs   left/NNNNNN.png, right/NNNNNN.png, timestamps.txt (seconds): stereod's `folder` source
//   --layout kitti   image_02/data, image_03/data and their timestamps.txt: a KITTI raw-data drive folder
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>

#include <CLI/CLI.hpp>
#include <opencv2/imgcodecs.hpp>

#include "drivers/replay/mcap_recording.hpp"
#include "tools/subcommands.hpp"

namespace stereod::tools {
namespace {

namespace fs = std::filesystem;

std::string kitti_time(int64_t ns)
{
	const std::time_t seconds = static_cast<std::time_t>(ns / 1'000'000'000);
	std::tm tm{};
	gmtime_r(&seconds, &tm);
	char text[64];
	std::snprintf(text, sizeof(text), "%04d-%02d-%02d %02d:%02d:%02d.%09lld", tm.tm_year + 1900, tm.tm_mon + 1,
		      tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, static_cast<long long>(ns % 1'000'000'000));
	return text;
}

int export_recording(const std::string &input, const std::string &output, const std::string &layout)
{
	const auto reader = drivers::open_recording(input);
	const auto &h = reader->recording_header();
	const bool kitti = layout == "kitti";
	const fs::path root(output);
	const fs::path left_dir = kitti ? root / "image_02" / "data" : root / "left";
	const fs::path right_dir = kitti ? root / "image_03" / "data" : root / "right";
	fs::create_directories(left_dir);
	if (h.geometry.stereo)
		fs::create_directories(right_dir);
	std::ofstream left_stamps(kitti ? root / "image_02" / "timestamps.txt" : root / "timestamps.txt");
	std::ofstream right_stamps;
	if (kitti && h.geometry.stereo)
		right_stamps.open(root / "image_03" / "timestamps.txt");
	// Which frames a camera delivered whole: tools comparing pixels skip the others (stereod records
	// incomplete frames too, so a lost packet is visible in the recording rather than hidden).
	std::ofstream statuses(root / "status.txt");
	StereoFrame frame;
	frame.allocate(h.geometry);
	uint64_t n = 0, not_ok = 0;
	while (reader->next_frame(frame)) {
		char name[32];
		std::snprintf(name, sizeof(name), kitti ? "%010llu.png" : "%06llu.png",
			      static_cast<unsigned long long>(n));
		if (!cv::imwrite((left_dir / name).string(), frame.left))
			throw std::runtime_error((left_dir / name).string() + ": cannot write");
		if (h.geometry.stereo && !cv::imwrite((right_dir / name).string(), frame.right))
			throw std::runtime_error((right_dir / name).string() + ": cannot write");
		if (kitti) {
			left_stamps << kitti_time(frame.device_ns) << "\n";
			if (h.geometry.stereo)
				right_stamps << kitti_time(frame.device_ns + frame.lr_skew_ns) << "\n";
		} else {
			char seconds[40];
			std::snprintf(seconds, sizeof(seconds), "%.9f", static_cast<double>(frame.device_ns) * 1e-9);
			left_stamps << seconds << "\n";
		}
		statuses << to_string(frame.status) << "\n";
		not_ok += frame.status != FrameStatus::Ok;
		++n;
	}
	std::cerr << "stereoctl export: " << n << " frames -> " << output << " (" << layout << "); ";
	if (not_ok > 0)
		std::cerr << not_ok << " of them incomplete or corrupt (status.txt); ";
	std::cerr << reader->describe_end() << "\n";
	if (!left_stamps || !statuses)
		throw std::runtime_error(output + ": cannot write timestamps");
	return n > 0 ? 0 : 1;
}

} // namespace

void add_export_command(CLI::App &app)
{
	auto *cmd = app.add_subcommand("export", "write a recording's frames as PNG pairs or a KITTI-layout folder");
	struct Options {
		std::string input, output, layout = "pairs";
	};
	auto options = std::make_shared<Options>();
	cmd->add_option("recording", options->input, "a .srec or .mcap recording")->required();
	cmd->add_option("-o,--output", options->output, "folder to write")->required();
	cmd->add_option("--layout", options->layout, "pairs (left/, right/: the folder source) | kitti")
		->check(CLI::IsMember({"pairs", "kitti"}));
	cmd->callback([options] {
		throw CLI::RuntimeError(export_recording(options->input, options->output, options->layout));
	});
}

} // namespace stereod::tools
