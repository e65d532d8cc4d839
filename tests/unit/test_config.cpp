#include <gtest/gtest.h>

#include <chrono>
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

TEST(Config, TextThatIsNotUtf8IsRefusedWithItsLine)
{
	// fuzz_config's find: invalid UTF-8 in a literal string made toml11 3.7 read past its buffer.
	std::string e = error_of("[sim]\n'so\xf6tputim.fps='e3\n");
	EXPECT_NE(e.find("c.toml:2: not valid UTF-8 (byte 0xF6)"), std::string::npos) << e;
	// An overlong '/', a surrogate, a lead byte with no continuation at the end of the file.
	for (const std::string bad : {"\xc0\xaf", "\xed\xa0\x80", "\xf0\x9f"}) {
		e = error_of("[output]\nsocket = \"/run/s" + bad + "\"\n");
		EXPECT_NE(e.find("c.toml:2: not valid UTF-8"), std::string::npos) << e;
	}
	// Valid UTF-8 of every length reaches the parser (and the key's own check).
	e = error_of("[output]\n# caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80\nsocket = \"/run/stereod/x.sock\"\n");
	EXPECT_EQ(e, "");
}

TEST(Config, StereoNeedsAWayToMatchTheRightEye)
{
	const std::string e = error_of("[stereo]\nright_features = false\nrow_search = false\n");
	EXPECT_NE(e.find("stereo.right_features = false needs stereo.row_search = true"), std::string::npos) << e;
	EXPECT_EQ(error_of("[stereo]\nright_features = false\n"), "");
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
	// TOML's octal form, as the default config shows the socket mode, is a number (it was taken as a word).
	apply_override("output.socket_mode=0o640", config);
	EXPECT_EQ(config.output.socket_mode, 0640);
	apply_override("output.socket_mode=0x1a4", config);
	EXPECT_EQ(config.output.socket_mode, 0644);
	// A word that only starts like one stays a word.
	apply_override("aravis.left=0xcamera", config);
	EXPECT_EQ(config.source.aravis.left, "0xcamera");
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

// Defects found by a hostile probe (issue 17, section 8): each of these crashed, hung or misled before.
TEST(ConfigDefects, DeeplyNestedArraysAreRefusedBeforeParsing)
{
	// 7,000 nested arrays overflowed the parser's stack (SIGSEGV), as a file and through --set.
	const std::string deep = std::string(7000, '[') + std::string(7000, ']');
	const std::string message = error_of("[pipeline]\nworkers = " + deep + "\n");
	EXPECT_NE(message.find(":2: arrays or tables nested deeper than 32"), std::string::npos) << message;
	DaemonConfig config;
	EXPECT_THROW(apply_override("pipeline.workers=" + deep, config), ConfigError);
	// Brackets inside strings and comments are not nesting.
	EXPECT_EQ(error_of("[output]\nsocket = \"/tmp/" + std::string(40, '[') + ".sock\" # " + std::string(50, '{') +
			   "\n"),
		  "")
		<< "brackets in strings counted";
}

TEST(ConfigDefects, HugeInputIsRefusedQuickly)
{
	std::string many = "[pipeline]\nworkers = [";
	for (int i = 0; i < 300000; ++i)
		many += "{a=1},";
	many += "]\n";
	const auto start = std::chrono::steady_clock::now();
	const std::string message = error_of(many);
	EXPECT_NE(message.find("larger than 1024 KiB"), std::string::npos) << message;
	EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(2));
}

TEST(ConfigDefects, OnlyARegularFileIsAConfig)
{
	DaemonConfig config;
	try {
		load_config_file(fs::temp_directory_path().string(), config);
		FAIL() << "a directory was accepted";
	} catch (const ConfigError &e) {
		EXPECT_NE(std::string(e.what()).find("not a regular file"), std::string::npos) << e.what();
	}
	try {
		load_config_file("/dev/zero", config);
		FAIL() << "/dev/zero was read as an empty config";
	} catch (const ConfigError &e) {
		EXPECT_NE(std::string(e.what()).find("/dev/zero: not a regular file"), std::string::npos) << e.what();
	}
}

TEST(ConfigDefects, ControlCharactersInOverridesAreRejected)
{
	DaemonConfig config;
	// A newline once let one override set another key (this one moved the socket).
	EXPECT_THROW(apply_override("log.level=info\n[output]\nsocket = \"/tmp/evil.sock\"", config), ConfigError);
	EXPECT_EQ(config.output.socket, "/tmp/stereod.sock");
	EXPECT_THROW(apply_override(std::string("sim.scene=default") + '\t', config), ConfigError);
}

TEST(ConfigDefects, SocketPathIsValidatedWithTheConfigAndEchoedShort)
{
	DaemonConfig config;
	try {
		apply_override("output.socket=\"\"", config);
		FAIL() << "an empty socket path was accepted";
	} catch (const ConfigError &e) {
		EXPECT_NE(std::string(e.what()).find("output.socket: must not be empty"), std::string::npos)
			<< e.what();
	}
	const std::string longer(10'000'000, 'x');
	try {
		apply_override("output.socket=/tmp/" + longer, config);
		FAIL() << "a 10 MB socket path was accepted";
	} catch (const ConfigError &e) {
		const std::string what = e.what();
		EXPECT_NE(what.find("output.socket"), std::string::npos) << what.substr(0, 200);
		EXPECT_LT(what.size(), 400U) << "the path was echoed in full";
	}
}

TEST(Config, AddressLikeBareWordsAreStrings)
{
	DaemonConfig config;
	apply_override("aravis.left=127.0.0.1", config);
	EXPECT_EQ(config.source.aravis.left, "127.0.0.1");
	apply_override("aravis.features=[\"ExposureAuto=Off\", \"GainAuto=Off\"]", config);
	ASSERT_EQ(config.source.aravis.features.size(), 2U);
	EXPECT_EQ(config.source.aravis.features[1], "GainAuto=Off");
	EXPECT_THROW(apply_override("aravis.layout=diagonal", config), ConfigError);
}
