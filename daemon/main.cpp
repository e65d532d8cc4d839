// stereod: the daemon, and its batch mode (`stereod process`).
#include <iostream>

#include <CLI/CLI.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "daemon/app.hpp"
#include "daemon/config.hpp"
#include "drivers/source.hpp"

using namespace stereod;

int main(int argc, char **argv)
{
	CLI::App app{"stereod: stereo camera motion daemon. Streams what moves around the camera over a Unix socket."};
	app.set_version_flag("--version", "stereod 0.1.0");
	std::string config_path;
	std::vector<std::string> overrides;
	bool print_config = false, list_sources = false;
	app.add_option("-c,--config", config_path, "TOML config file (see config/stereod.toml)");
	app.add_option("-s,--set", overrides, "override one option: section.key=value (repeatable)")
		->allow_extra_args(false);
	app.add_flag("--print-config", print_config, "print every option at its default and exit");
	app.add_flag("--list-sources", list_sources, "list the capture drivers and exit");

	auto *process =
		app.add_subcommand("process", "run the pipeline over a recording, dataset or video into NDJSON");
	std::string input, format = "auto";
	daemon::BatchOptions batch;
	bool no_progress = false;
	process->add_option("-i,--input", input, "recording (.srec, .mcap), dataset folder or video file")->required();
	process->add_option(
		"-f,--format", format,
		"auto | recording | video | kitti | euroc | tum | folder | sim (auto guesses from the path)");
	process->add_option("-o,--output", batch.output,
			    "results: NDJSON file, - for standard output, or MCAP for a .mcap path")
		->required();
	process->add_flag("--images", batch.images,
			  "MCAP output: the images too, as JPEG (foxglove.CompressedImage), so Foxglove shows them");
	process->add_option("--truth-dir", batch.truth_dir, "write the source's ground truth (sim) here");
	process->add_flag("--no-progress", no_progress, "no progress bar");
	process->fallthrough(); // --config and --set work after `process` too

	CLI11_PARSE(app, argc, argv);
	// Logs go to standard error: standard output may carry results (`process --output -`, `watch`).
	spdlog::set_default_logger(spdlog::stderr_color_mt("stereod"));
	spdlog::set_pattern("%Y-%m-%d %H:%M:%S.%e %^%l%$ %v");

	try {
		if (print_config) {
			std::cout << daemon::default_config_text();
			return 0;
		}
		if (list_sources) {
			const auto registry = drivers::SourceRegistry::with_builtin_drivers();
			for (const auto &name : registry.names())
				std::cout << name << "\t" << registry.summary(name) << "\n";
			return 0;
		}
		// The file, then the overrides: at start, and again on SIGHUP (the overrides keep applying).
		const auto load = [&config_path, &overrides] {
			daemon::DaemonConfig loaded;
			if (!config_path.empty())
				daemon::load_config_file(config_path, loaded);
			for (const auto &assignment : overrides)
				daemon::apply_override(assignment, loaded);
			return loaded;
		};
		daemon::DaemonConfig config = load();

		if (*process) {
			config.source.driver = daemon::driver_for_format(format, input);
			config.source.path = input;
			if (config.source.driver == "sim")
				config.source.path.clear();
			config.source.rate = drivers::ReplayRate::Fast;
			batch.progress = !no_progress;
			return daemon::run_batch(config, batch);
		}
		return daemon::run_daemon(config, config_path.empty() ? std::function<daemon::DaemonConfig()>() : load);
	} catch (const daemon::ConfigError &e) {
		std::cerr << "stereod: " << e.what() << "\n";
		return 2;
	} catch (const drivers::SourceError &e) {
		std::cerr << "stereod: " << e.what() << "\n";
		return 2;
	} catch (const std::exception &e) {
		std::cerr << "stereod: " << e.what() << "\n";
		return 1;
	}
}
