// Benchmark (not a test): the daemon's pipeline on the live sim at its frame rate, capture-to-publish
// latency percentiles and throughput, with the vision stages off (the spine alone), on the left eye (the
// monocular ORB path) and on the whole stereo path (both eyes' features, stereo, pose, geometric check).
#include <cstdio>
#include <map>
#include <mutex>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include "core/latency.hpp"
#include "daemon/app.hpp"
#include "daemon/pipeline.hpp"

using namespace stereod;

namespace {

struct Run {
	protocol::LatencySummary latency;
	double fps = 0;
	daemon::PipelineStats stats;
	std::map<std::string, double> stage_ms; ///< mean per published frame
};

enum class Path { Spine, Mono, Stereo };

Run run(const drivers::SourceConfig &source_config, Path path, double seconds, size_t workers)
{
	auto source = drivers::SourceRegistry::with_builtin_drivers().create(source_config);
	daemon::PipelineOptions options;
	options.workers = workers;
	options.overflow = OverflowPolicy::DropOldest;
	options.motion.enabled = path != Path::Spine;
	if (path == Path::Stereo)
		options.motion.rig = source->info().calibration; // both eyes' features, stereo, pose, geometric check
	std::mutex m;
	std::vector<int64_t> latencies;
	std::map<std::string, double> stages;
	daemon::Pipeline pipeline(std::move(source), options, [&](FrameResult &r) {
		std::lock_guard lock(m);
		latencies.push_back(r.t_publish_ns - r.t_host_ns);
		for (const auto &t : r.timing)
			stages[t.name] += t.ms;
	});
	pipeline.start();
	std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
	pipeline.request_stop();
	pipeline.wait();
	Run out;
	out.stats = pipeline.stats();
	out.latency = summarize_ns(latencies);
	out.fps = static_cast<double>(latencies.size()) / seconds;
	const double n = std::max<double>(1, static_cast<double>(latencies.size()));
	for (const auto &[name, ms] : stages)
		out.stage_ms[name] = ms / n;
	return out;
}

void row(const char *name, const Run &r)
{
	const auto stage = [&](const char *key) {
		const auto it = r.stage_ms.find(key);
		return it == r.stage_ms.end() ? 0.0 : it->second;
	};
	std::printf("| %-28s | %6.1f | %7.2f | %7.2f | %7.2f | %7.2f | %6llu | %6llu | %6.2f | %6.2f | %6.2f | %6.2f | "
		    "%6.2f |\n",
		    name, r.fps, r.latency.p50_ms, r.latency.p90_ms, r.latency.p99_ms, r.latency.max_ms,
		    static_cast<unsigned long long>(r.stats.ring_evicted),
		    static_cast<unsigned long long>(r.stats.pool_exhausted), stage("extract"), stage("stereo"),
		    stage("match") + stage("subpixel"), stage("classify"), stage("pose"));
}

} // namespace

int main(int argc, char **argv)
{
	CLI::App app{"capture-to-publish latency on the live sim"};
	double seconds = 20;
	int width = 1024, height = 768;
	double fps = 30;
	size_t workers = daemon::default_workers();
	std::string scene = "default";
	app.add_option("-t,--seconds", seconds, "seconds per run");
	app.add_option("--width", width);
	app.add_option("--height", height);
	app.add_option("--fps", fps);
	app.add_option("--workers", workers);
	app.add_option("--scene", scene);
	CLI11_PARSE(app, argc, argv);
	spdlog::set_level(spdlog::level::warn);

	drivers::SourceConfig config;
	config.realtime = true;
	config.sim.width = width;
	config.sim.height = height;
	config.sim.fps = fps;
	config.sim.scene = scene;
	std::printf("sim '%s' %dx%d stereo at %.0f fps, %zu workers, %.0f s per run, drop-oldest\n\n", scene.c_str(),
		    width, height, fps, workers, seconds);
	std::printf("| %-28s | %6s | %7s | %7s | %7s | %7s | %6s | %6s | %6s | %6s | %6s | %6s | %6s |\n", "pipeline",
		    "fps", "p50 ms", "p90 ms", "p99 ms", "max ms", "ring", "pool", "extr.", "stereo", "match", "class.",
		    "pose");
	std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
	row("spine only (vision off)", run(config, Path::Spine, seconds, workers));
	row("ORB + seed-000 (left eye)", run(config, Path::Mono, seconds, workers));
	row("stereo: both eyes, pose", run(config, Path::Stereo, seconds, workers));
	std::printf("\nlatency = t_publish - t_host (capture complete on the host -> message handed to the socket);\n"
		    "ring/pool = frames dropped by drop-oldest / for want of a free frame; stage columns: mean ms per "
		    "frame.\n");
	return 0;
}
