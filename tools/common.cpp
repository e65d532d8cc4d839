#include "tools/common.hpp"

#include <fstream>
#include <iostream>

#include <nlohmann/json.hpp>

#include "core/protocol.hpp"
#include "daemon/app.hpp"
#include "drivers/replay/mcap.hpp"
#include "drivers/replay/mcap_recording.hpp"

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

namespace {

/// The results channel of an MCAP file (docs/mcap.md): the same `frame` messages as NDJSON.
std::map<uint64_t, FrameResult> read_mcap_results(const std::string &path)
{
	drivers::mcap::Reader reader(path);
	std::map<uint64_t, FrameResult> results;
	drivers::mcap::MessageView m;
	uint64_t number = 0;
	while (reader.next(m)) {
		if (m.channel->topic != drivers::kMcapResultsTopic)
			continue;
		++number;
		try {
			FrameResult result =
				protocol::parse_frame_message(nlohmann::json::parse(m.data.begin(), m.data.end()));
			results[result.seq] = std::move(result);
		} catch (const std::exception &e) {
			throw std::runtime_error(path + ": " + drivers::kMcapResultsTopic + " message " +
						 std::to_string(number) + ": " + e.what());
		}
	}
	if (!reader.report().clean_end)
		std::cerr << path << ": " << reader.report().describe() << "\n";
	if (number == 0)
		throw std::runtime_error(path + ": no results in it (no " + drivers::kMcapResultsTopic +
					 " messages: a recording of frames? run stereod process over it)");
	return results;
}

} // namespace

std::map<uint64_t, FrameResult> read_results(const std::string &path)
{
	if (drivers::mcap::is_mcap_file(path))
		return read_mcap_results(path);
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
