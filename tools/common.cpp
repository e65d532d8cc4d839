#include "tools/common.hpp"

#include <fstream>

#include <nlohmann/json.hpp>

#include "core/protocol.hpp"
#include "daemon/app.hpp"

namespace stereod::tools {

daemon::DaemonConfig load_config(const SourceOptions &options)
{
	daemon::DaemonConfig config;
	if (!options.config_path.empty())
		daemon::load_config_file(options.config_path, config);
	for (const auto &assignment : options.overrides)
		daemon::apply_override(assignment, config);
	if (!options.input.empty()) {
		config.source.driver = daemon::driver_for_format(options.format, options.input);
		config.source.path = config.source.driver == "sim" ? "" : options.input;
	} else if (options.format != "auto") {
		config.source.driver = daemon::driver_for_format(options.format, "");
	}
	config.source.realtime = options.realtime;
	config.source.rate = options.realtime ? drivers::ReplayRate::Recorded : drivers::ReplayRate::Fast;
	return config;
}

std::unique_ptr<drivers::FrameSource> open_source(const SourceOptions &options)
{
	const auto config = load_config(options);
	return drivers::SourceRegistry::with_builtin_drivers().create(config.source);
}

std::map<uint64_t, FrameResult> read_results(const std::string &path)
{
	std::ifstream in(path);
	if (!in)
		throw std::runtime_error(path + ": cannot read results");
	std::map<uint64_t, FrameResult> results;
	std::string line;
	int number = 0;
	while (std::getline(in, line)) {
		++number;
		if (line.empty())
			continue;
		try {
			const auto message = nlohmann::json::parse(line);
			if (message.value("type", "") != "frame")
				continue;
			FrameResult result = protocol::parse_frame_message(message);
			results[result.seq] = std::move(result);
		} catch (const std::exception &e) {
			throw std::runtime_error(path + ":" + std::to_string(number) + ": " + e.what());
		}
	}
	return results;
}

} // namespace stereod::tools
