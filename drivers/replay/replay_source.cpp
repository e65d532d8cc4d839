// The `replay` driver: plays a recording, .srec or MCAP (drivers/replay/mcap_recording.hpp).
#include "core/clock.hpp"
#include "drivers/builtin.hpp"
#include "drivers/replay/pacer.hpp"
#include "drivers/replay/recording.hpp"

namespace stereod::drivers {
namespace {

class ReplaySource final : public FrameSource
{
public:
	explicit ReplaySource(const SourceConfig &config) : pacer_(config.rate)
	{
		if (config.path.empty())
			throw SourceError("replay: no recording given (source.path)");
		try {
			reader_ = open_recording(config.path);
		} catch (const std::exception &e) {
			throw SourceError(e.what());
		}
		const RecordingHeader &header = reader_->recording_header();
		info_.name = "replay";
		info_.description = config.path + " (recorded from " + header.source + ": " + header.description + ")";
		info_.geometry = header.geometry;
		info_.live = false;
	}

	const SourceInfo &info() const override { return info_; }

	GrabStatus grab(StereoFrame &into) override
	{
		if (!reader_->next_frame(into))
			return GrabStatus::EndOfStream;
		if (!pacer_.wait_for(into.device_ns))
			return GrabStatus::EndOfStream;
		into.host_ns = monotonic_ns(); // the recorded host time belongs to the recording machine
		return GrabStatus::Frame;
	}

	std::vector<std::string> report() const override { return {"replay: " + reader_->describe_end()}; }

private:
	std::unique_ptr<FrameRecordingReader> reader_;
	Pacer pacer_;
	SourceInfo info_;
};

} // namespace

void register_replay(SourceRegistry &registry)
{
	registry.add("replay", "a stereod recording (.srec or .mcap)",
		     [](const SourceConfig &config) { return std::make_unique<ReplaySource>(config); });
}

} // namespace stereod::drivers
