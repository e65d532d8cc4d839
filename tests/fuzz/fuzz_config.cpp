// libFuzzer target: the config parser, as a file (--config) and as overrides (--set). Bad input must end in
// ConfigError (file, line and key named), never in a crash, a hang or unbounded memory (issue 17 section 8:
// a config nested 7,000 deep used to overflow the stack).
#include <stdexcept>
#include <string>

#include "daemon/config.hpp"
#include "tests/fuzz/fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	using namespace stereod::daemon;
	DaemonConfig config;
	try {
		load_config_file(stereod::fuzz::as_file(data, size, ".toml"), config);
		validate(config, "fuzz");
	} catch (const ConfigError &) {
	}
	// Every line as an override, as `stereod --set LINE` would take it.
	const std::string text(reinterpret_cast<const char *>(data), size);
	size_t start = 0;
	for (int lines = 0; start <= text.size() && lines < 64; ++lines) {
		const size_t end = std::min(text.find('\n', start), text.size());
		try {
			DaemonConfig overridden;
			apply_override(text.substr(start, end - start), overridden);
		} catch (const ConfigError &) {
		}
		start = end + 1;
	}
	return 0;
}
