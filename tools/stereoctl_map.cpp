// stereoctl map: the static scene as a PLY point cloud, movers left out (core/geometry/static_map.hpp), from
// a results file of `stereod process`; with --colour, coloured from the left images of the source the results
// were made from (the same --input / --set as for stereod process).
#include <fstream>
#include <iostream>
#include <memory>

#include <CLI/CLI.hpp>

#include "core/geometry/static_map.hpp"
#include "drivers/source.hpp"
#include "tools/common.hpp"
#include "tools/subcommands.hpp"

namespace stereod::tools {
namespace {

struct MapOptions {
	std::string results, output;
	bool colour = false;
	bool keyframes_only = false;
	SourceOptions source;
	geometry::StaticMapParams params;
};

void write_ply(const std::string &path, const std::vector<geometry::MapPoint> &points)
{
	std::ofstream out(path);
	if (!out)
		throw std::runtime_error(path + ": cannot create");
	out << "ply\nformat ascii 1.0\ncomment stereod static map: world = the first frame's left camera (x right, "
	       "y down, z forward), metres\nelement vertex "
	    << points.size()
	    << "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar "
	       "green\nproperty uchar blue\nproperty int observations\nend_header\n";
	for (const auto &p : points)
		out << p.xyz_m[0] << ' ' << p.xyz_m[1] << ' ' << p.xyz_m[2] << ' ' << int{p.colour[2]} << ' '
		    << int{p.colour[1]} << ' ' << int{p.colour[0]} << ' ' << p.observations << '\n';
	if (!out)
		throw std::runtime_error(path + ": write failed");
}

int make_map(const MapOptions &options)
{
	const auto results = read_results(options.results);
	geometry::StaticMap map(options.params);
	uint64_t frames = 0, added = 0;
	// Seed 001 builds its map from keyframes: with --keyframes only frames marked `ego.keyframe` add points.
	const auto wanted = [&options](const FrameResult &result) {
		return !options.keyframes_only || (result.ego && result.ego->keyframe && *result.ego->keyframe);
	};
	if (!options.colour) {
		for (const auto &[seq, result] : results) {
			++frames;
			if (wanted(result))
				added += static_cast<uint64_t>(map.add(result));
		}
	} else {
		auto source = open_source(options.source);
		StereoFrame frame;
		frame.allocate(source->info().geometry);
		const uint64_t last = results.empty() ? 0 : results.rbegin()->first;
		while (source->grab(frame) == drivers::GrabStatus::Frame && frame.sequence <= last) {
			const auto it = results.find(frame.sequence);
			if (it == results.end())
				continue;
			++frames;
			if (wanted(it->second))
				added += static_cast<uint64_t>(map.add(it->second, frame.left));
		}
	}
	const auto points = map.points();
	write_ply(options.output, points);
	std::cerr << "stereoctl map: " << points.size() << " points (voxels of " << options.params.voxel_m
		  << " m seen in at least " << options.params.min_observations << " frames) from " << added
		  << " static points of " << map.frames_used() << " posed frames (of " << frames << ") -> "
		  << options.output << "\n";
	return points.empty() ? 1 : 0;
}

} // namespace

void add_map_command(CLI::App &app)
{
	auto *cmd = app.add_subcommand("map", "write the static scene, movers left out, as a PLY point cloud");
	auto options = std::make_shared<MapOptions>();
	cmd->add_option("-r,--results", options->results, "NDJSON from stereod process (stereo or RGB-D)")->required();
	cmd->add_flag("--colour", options->colour,
		      "colour the points from the source the results came from (--input, --format, --set)");
	cmd->add_flag("--keyframes", options->keyframes_only,
		      "only keyframes add points (ego.keyframe; seed 001 builds its map from them)");
	cmd->add_option("-c,--config", options->source.config_path, "stereod config file (for --colour)");
	cmd->add_option("-s,--set", options->source.overrides, "override: section.key=value (for --colour)")
		->allow_extra_args(false);
	cmd->add_option("-i,--input", options->source.input, "recording, dataset folder or video (for --colour)");
	cmd->add_option("-f,--format", options->source.format, "auto | recording | video | kitti | euroc | tum | sim");
	cmd->add_option("-o,--output", options->output, "PLY file to write")->required();
	cmd->add_option("--voxel", options->params.voxel_m, "grid cell edge, metres")
		->capture_default_str()
		->check(CLI::Range(0.001, 10.0));
	cmd->add_option("--min-observations", options->params.min_observations, "frames a cell must be seen in")
		->capture_default_str()
		->check(CLI::Range(1, 1000));
	cmd->add_option("--max-depth", options->params.max_depth_m, "leave out points farther than this, metres")
		->capture_default_str();
	cmd->callback([options] { throw CLI::RuntimeError(make_map(*options)); });
}

} // namespace stereod::tools
