// libFuzzer target: a frame message as clients (stereoctl watch, eval, map) parse it from the socket or an
// NDJSON file. Anything that is not a valid message must throw (and be reported by the caller), never crash.
#include <exception>
#include <string>

#include <nlohmann/json.hpp>

#include "core/protocol.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	using namespace stereod;
	try {
		const auto json = nlohmann::json::parse(std::string(reinterpret_cast<const char *>(data), size));
		const FrameResult result = protocol::parse_frame_message(json);
		// What was read must serialise again.
		(void)protocol::frame_message(result);
	} catch (const std::exception &) {
	}
	return 0;
}
