#include <sstream>

#include "drivers/source.hpp"

namespace stereod::drivers {

void SourceRegistry::add(std::string name, std::string summary, Factory factory)
{
	entries_[std::move(name)] = {std::move(summary), std::move(factory)};
}

std::unique_ptr<FrameSource> SourceRegistry::create(const SourceConfig &config) const
{
	const auto it = entries_.find(config.driver);
	if (it == entries_.end()) {
		std::ostringstream known;
		for (const auto &[name, entry] : entries_)
			known << (known.tellp() > 0 ? ", " : "") << name;
		throw SourceError("unknown source driver '" + config.driver + "' (known: " + known.str() + ")");
	}
	return it->second.factory(config);
}

std::vector<std::string> SourceRegistry::names() const
{
	std::vector<std::string> out;
	for (const auto &[name, entry] : entries_)
		out.push_back(name);
	return out;
}

const std::string &SourceRegistry::summary(const std::string &name) const
{
	return entries_.at(name).summary;
}

} // namespace stereod::drivers
