// `stereoctl eval --poses`: the camera trajectory a run estimated (ego.T_world_curr of each frame) against
// ground truth in the TUM or the KITTI poses format: ATE, RPE and KITTI-style drift (tools/trajectory.hpp).
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "tools/common.hpp"
#include "tools/subcommands.hpp"
#include "tools/trajectory.hpp"

namespace stereod::tools {

namespace fs = std::filesystem;

namespace {

/// A truth folder (stereod process --truth-dir) holds poses.tum; a file is TUM unless every data line has 12
/// numbers (KITTI).
std::vector<StampedPose> read_truth(const std::string &path, bool &by_index)
{
	fs::path file = path;
	if (fs::is_directory(file))
		file /= "poses.tum";
	std::ifstream in(file);
	if (!in)
		throw std::runtime_error(file.string() +
					 ": cannot open (a TUM or KITTI poses file, or a --truth-dir folder)");
	std::string line;
	while (std::getline(in, line)) {
		if (line.empty() || line[0] == '#')
			continue;
		std::istringstream fields(line);
		size_t count = 0;
		for (double v; fields >> v;)
			++count;
		by_index = count == 12;
		break;
	}
	return by_index ? read_kitti_poses(file.string()) : read_tum(file.string());
}

nlohmann::json stats_json(const ErrorStats &s)
{
	return {{"count", s.count},   {"rmse", s.rmse}, {"mean", s.mean},
		{"median", s.median}, {"std", s.std},	{"max", s.max}};
}

std::string stats_row(const std::string &name, const ErrorStats &s, double scale, const std::string &unit)
{
	std::ostringstream out;
	out << std::fixed << std::setprecision(4) << "| " << name << " (" << unit << ") | " << s.rmse * scale << " | "
	    << s.mean * scale << " | " << s.median * scale << " | " << s.std * scale << " | " << s.max * scale << " | "
	    << s.count << " |\n";
	return out.str();
}

} // namespace

int eval_trajectory(const TrajectoryEvalOptions &options)
{
	const auto results = read_results(options.results);
	bool by_index = false;
	const std::vector<StampedPose> truth = read_truth(options.poses, by_index);
	std::vector<StampedPose> estimate;
	size_t invalid = 0, index = 0;
	for (const auto &[seq, result] : results) {
		const size_t this_index = index++;
		if (!result.ego || !result.ego->t_world_curr)
			continue;
		if (result.ego->valid && !*result.ego->valid)
			++invalid;
		StampedPose p;
		p.t_s = by_index ? static_cast<double>(this_index) : static_cast<double>(result.t_capture_ns) * 1e-9;
		p.pose = geometry::Pose::from_matrix(*result.ego->t_world_curr);
		estimate.push_back(p);
	}
	if (estimate.empty()) {
		std::cerr << "stereoctl eval: no frame of " << options.results
			  << " has a pose (ego.T_world_curr): was the source stereo and calibrated?\n";
		return 1;
	}
	if (!options.write_estimate.empty())
		write_tum(options.write_estimate, estimate);
	const Association pairs = associate(estimate, truth, by_index ? 0.5 : options.max_dt_s);
	if (pairs.estimate.size() < 2) {
		std::cerr << "stereoctl eval: only " << pairs.estimate.size() << " of " << estimate.size()
			  << " poses have a truth pose within " << options.max_dt_s << " s\n";
		return 1;
	}
	const AbsoluteError ate = absolute_trajectory_error(pairs.estimate, pairs.truth);
	const RelativeError rpe = relative_pose_error(pairs.estimate, pairs.truth, options.delta);
	const Drift d = drift(pairs.estimate, pairs.truth, options.window);
	double length = 0;
	for (size_t i = 1; i < pairs.truth.size(); ++i)
		length += cv::norm(pairs.truth[i].t - pairs.truth[i - 1].t);

	if (options.json) {
		std::cout << nlohmann::json{{"name", options.name},
					    {"poses", pairs.estimate.size()},
					    {"not_estimated", invalid},
					    {"length_m", length},
					    {"ate_m", stats_json(ate.translation_m)},
					    {"rpe_delta", options.delta},
					    {"rpe_translation_m", stats_json(rpe.translation_m)},
					    {"rpe_rotation_deg", stats_json(rpe.rotation_deg)},
					    {"drift_window", options.window},
					    {"drift_windows", d.windows},
					    {"drift_translation_percent", d.translation_percent},
					    {"drift_rotation_deg_per_m", d.rotation_deg_per_m}}
				     .dump()
			  << '\n';
		return 0;
	}
	std::cout << options.name << ": " << pairs.estimate.size() << " poses (" << invalid
		  << " carried over, not estimated), path " << std::fixed << std::setprecision(2) << length << " m\n\n"
		  << "| error | RMSE | mean | median | std | max | n |\n|---|---|---|---|---|---|---|\n"
		  << stats_row("ATE", ate.translation_m, 100, "cm")
		  << stats_row("RPE translation, " + std::to_string(options.delta) + " frame(s)", rpe.translation_m,
			       1000, "mm")
		  << stats_row("RPE rotation, " + std::to_string(options.delta) + " frame(s)", rpe.rotation_deg, 1,
			       "deg")
		  << "\ndrift over " << options.window << "-frame windows (" << d.windows << " windows): translation "
		  << std::setprecision(3) << d.translation_percent << " %, rotation " << std::setprecision(4)
		  << d.rotation_deg_per_m << " deg/m\n";
	return 0;
}

} // namespace stereod::tools
