// stereoctl reference: masks of moving pixels for footage from a camera that stands still
// (tools/motion_reference.hpp), written as a truth folder `stereoctl eval --truth` reads: masks/%06d.png
// and truth.ndjson. Two passes over the source: one to sample the empty scene, one to write the masks.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "drivers/source.hpp"
#include "tools/common.hpp"
#include "tools/motion_reference.hpp"
#include "tools/subcommands.hpp"

namespace fs = std::filesystem;

namespace stereod::tools {
namespace {

struct ReferenceOptions {
	SourceOptions source;
	std::string output;
	int samples = 60;
	int max_frames = 0;
	MotionReferenceParams params;
};

int make_reference(const ReferenceOptions &options)
{
	// Pass 1: the empty scene, from frames sampled evenly over the whole source.
	auto source = open_source(options.source);
	const uint64_t announced = source->info().frame_count;
	if (announced == 0)
		throw std::runtime_error("the source does not say how many frames it has: give a video or recording");
	const uint64_t total = options.max_frames > 0
				       ? std::min<uint64_t>(announced, static_cast<uint64_t>(options.max_frames))
				       : announced;
	const uint64_t step = std::max<uint64_t>(1, total / static_cast<uint64_t>(options.samples));
	std::vector<cv::Mat> samples;
	StereoFrame frame;
	frame.allocate(source->info().geometry);
	uint64_t index = 0;
	while (index < total && source->grab(frame) == drivers::GrabStatus::Frame) {
		if (index % step == 0)
			samples.push_back(frame.left.clone());
		++index;
	}
	if (samples.size() < 3)
		throw std::runtime_error("too few frames to sample the background (" + std::to_string(samples.size()) +
					 ")");
	const cv::Mat background = median_background(samples);
	samples.clear();

	// Pass 2: each frame's movers.
	fs::create_directories(fs::path(options.output) / "masks");
	cv::imwrite((fs::path(options.output) / "background.png").string(), background);
	std::ofstream truth(fs::path(options.output) / "truth.ndjson", std::ios::trunc);
	source = open_source(options.source);
	uint64_t written = 0;
	double coverage = 0;
	while (written < total && source->grab(frame) == drivers::GrabStatus::Frame) {
		const cv::Mat mask = mover_mask(frame.left, background, options.params);
		char name[32];
		std::snprintf(name, sizeof(name), "masks/%06llu.png", static_cast<unsigned long long>(frame.sequence));
		if (!cv::imwrite((fs::path(options.output) / name).string(), mask))
			throw std::runtime_error(options.output + "/" + name + ": cannot write");
		// No "objects": the movers are known by their pixels only (tools/group_eval.hpp).
		truth << nlohmann::json{{"seq", frame.sequence}, {"t_capture_ns", frame.device_ns}, {"mask", name}}
				 .dump()
		      << '\n';
		coverage += static_cast<double>(cv::countNonZero(mask)) / static_cast<double>(mask.total());
		++written;
	}
	std::cerr << "stereoctl reference: " << written << " masks from a background of " << (total + step - 1) / step
		  << " sampled frames; movers cover "
		  << (written > 0 ? 100.0 * coverage / static_cast<double>(written) : 0.0)
		  << "% of a frame on average -> " << options.output << "\n";
	return written > 0 ? 0 : 1;
}

} // namespace

void add_reference_command(CLI::App &app)
{
	auto *cmd = app.add_subcommand(
		"reference", "masks of moving pixels for footage from a still camera (a truth folder for eval)");
	auto options = std::make_shared<ReferenceOptions>();
	cmd->add_option("-i,--input", options->source.input, "video or recording (the camera must stand still)")
		->required();
	cmd->add_option("-f,--format", options->source.format, "auto | recording | video");
	cmd->add_option("-c,--config", options->source.config_path, "stereod config file");
	cmd->add_option("-s,--set", options->source.overrides, "override: section.key=value")->allow_extra_args(false);
	cmd->add_option("-o,--output", options->output, "folder to write masks/ and truth.ndjson to")->required();
	cmd->add_option("--samples", options->samples, "frames sampled for the empty scene")
		->capture_default_str()
		->check(CLI::Range(3, 1000));
	cmd->add_option("--frames", options->max_frames, "only the first N frames (0: all)")->capture_default_str();
	cmd->add_option("--threshold", options->params.threshold, "colour difference that makes a pixel a mover's")
		->capture_default_str()
		->check(CLI::Range(1, 255));
	cmd->add_option("--min-area", options->params.min_area_px, "smallest blob kept, pixels")
		->capture_default_str()
		->check(CLI::Range(1, 1000000));
	cmd->callback([options] { throw CLI::RuntimeError(make_reference(*options)); });
}

} // namespace stereod::tools
