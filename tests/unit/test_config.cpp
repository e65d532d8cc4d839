#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include <toml.hpp>

#include "daemon/config.hpp"

using namespace stereod::daemon;
namespace fs = std::filesystem;

namespace {

std::string write_temp(const std::string &name, const std::string &text)
{
	const fs::path path = fs::temp_directory_path() / ("stereod-test-" + std::to_string(::getpid()) + "-" + name);
	std::ofstream(path) << text;
	return path.string();
}

std::string error_of(const std::string &text)
{
	DaemonConfig config;
	const std::string path = write_temp("c.toml", text);
	try {
		load_config_file(path, config);
	} catch (const ConfigError &e) {
		fs::remove(path);
		return e.what();
	}
	fs::remove(path);
	return "";
}

} // namespace

TEST(Config, ReadsValuesOverDefaults)
{
	DaemonConfig config;
	const std::string path =
		write_temp("ok.toml", "[sim]\nscene = \"toward\"\nwidth = 640\n[output]\nsocket_mode = 0o600\n"
				      "[classifier]\ntexture_threshold = 12.5\n");
	load_config_file(path, config);
	fs::remove(path);
	EXPECT_EQ(config.source.sim.scene, "toward");
	EXPECT_EQ(config.source.sim.width, 640);
	EXPECT_EQ(config.source.sim.height, 768) << "untouched keys keep their default";
	EXPECT_EQ(config.output.socket_mode, 0600);
	EXPECT_DOUBLE_EQ(config.motion.classifier.texture_threshold, 12.5);
}

TEST(Config, UnknownKeyNamesFileLineAndKey)
{
	const std::string e = error_of("[sim]\nwidth = 640\nwidht = 640\n");
	EXPECT_NE(e.find("c.toml:3:"), std::string::npos) << e;
	EXPECT_NE(e.find("unknown key 'sim.widht'"), std::string::npos) << e;
}

TEST(Config, UnknownSectionIsRejected)
{
	const std::string e = error_of("[output]\nsocket = \"/tmp/x\"\n[outptu]\nsocket = \"/tmp/x\"\n");
	EXPECT_NE(e.find("outptu"), std::string::npos) << e;
	EXPECT_NE(e.find("c.toml:"), std::string::npos) << e;
}

TEST(Config, OutOfRangeValueNamesTheRange)
{
	const std::string e = error_of("[pipeline]\n\nring_capacity = 0\n");
	EXPECT_NE(e.find("c.toml:3: pipeline.ring_capacity: must be between 1 and 1024 (got 0)"), std::string::npos)
		<< e;
}

TEST(Config, WrongTypeAndBadChoice)
{
	EXPECT_NE(error_of("[sim]\nstereo = \"yes\"\n").find("c.toml:2: sim.stereo: must be true or false"),
		  std::string::npos);
	EXPECT_NE(error_of("[sim]\nscene = \"beach\"\n").find("must be one of"), std::string::npos);
	EXPECT_NE(error_of("[sim]\nwidth = 640.5\n").find("must be an integer"), std::string::npos);
}

TEST(Config, MalformedLineIsASyntaxErrorWithItsLine)
{
	const std::string e = error_of("[sim]\nwidth = 640\nheight 480\n");
	EXPECT_NE(e.find("c.toml:3: syntax error"), std::string::npos) << e;
}

TEST(Config, TextureWeightsMustSumToOne)
{
	const std::string e = error_of("[classifier]\nalpha = 0.5\nbeta = 0.5\ngamma = 0.5\n");
	EXPECT_NE(e.find("must be 1 (eq. 4)"), std::string::npos) << e;
}

TEST(Config, OverridesTakeBareWordsAndNumbers)
{
	DaemonConfig config;
	apply_override("source.driver=video", config);
	apply_override("sim.fps=15", config);
	apply_override("sim.stereo=false", config);
	EXPECT_EQ(config.source.driver, "video");
	EXPECT_DOUBLE_EQ(config.source.sim.fps, 15.0);
	EXPECT_FALSE(config.source.sim.stereo);
	EXPECT_THROW(apply_override("sim.nope=1", config), ConfigError);
	EXPECT_THROW(apply_override("sim.width=1", config), ConfigError);
}

TEST(Config, DefaultConfigTextParsesBackToTheDefaults)
{
	const std::string path = write_temp("defaults.toml", default_config_text());
	DaemonConfig config;
	config.source.sim.width = 1; // must be overwritten by the file
	EXPECT_NO_THROW(load_config_file(path, config));
	fs::remove(path);
	EXPECT_EQ(config.source.sim.width, DaemonConfig{}.source.sim.width);
	EXPECT_EQ(config.output.socket_mode, DaemonConfig{}.output.socket_mode);
}
