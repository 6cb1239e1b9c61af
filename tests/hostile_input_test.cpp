// Hostile inputs at the motion reader, the .vtp reader, `merge`, `view`, `--out`, signals, a full
// disk and the library API. Each test gives one hostile input and checks what FibreMSS does with
// it; docs/bad-inputs.md lists them with the exit codes.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "fibremss/Error.h"
#include "fibremss/Output.h"
#include "fibremss/VtkFiles.h"
#include "support/HostileFiles.h"

namespace fibremss {
namespace {

namespace fs = std::filesystem;
using testing::cli;
using testing::filesIn;
using testing::ProcessResult;
using testing::TemporaryDirectory;
using testing::writeFile;
using testing::writeScene;

// --- --out: the user's files and the lock ----------------------------------------------------

TEST(HostileInputs, AUserFileNamedLikeATemporaryBelowOutIsKept) {
  TemporaryDirectory dir("fibremss_user_tmp");
  const fs::path out = dir.path() / "out";
  fs::create_directories(out / "mine");
  writeFile(out / "mine" / "data.tmp.123.4", "the user's own file");
  writeFile(out / "notes.tmp.1.1", "the user's own file");
  { const OutputDirectory first(out.string()); }  // a writer that finished
  const OutputDirectory second(out.string());
  EXPECT_EQ(second.removedTemporaries(), 0u);
  EXPECT_TRUE(fs::exists(out / "mine" / "data.tmp.123.4"));
  EXPECT_TRUE(fs::exists(out / "notes.tmp.1.1"));
}

TEST(HostileInputs, ALockFileThatIsASymbolicLinkIsNotFollowed) {
  TemporaryDirectory dir("fibremss_lock_link");
  const fs::path out = dir.path() / "out";
  fs::create_directories(out);
  fs::create_symlink(dir.path() / "outside", out / ".fibremss.lock");
  try {
    const OutputDirectory locked(out.string());
    FAIL() << "followed the link";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(".fibremss.lock"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("symbolic link"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir.path() / "outside"));
  const ProcessResult result = cli("check fusiform --out " + out.string());
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_FALSE(fs::exists(dir.path() / "outside"));
}

// --- merge ------------------------------------------------------------------------------------

/// A summary `merge` accepts: one run.
const char* const kSummary = R"({"runs": [{"method": "fibremss"}]})";

TEST(HostileInputs, MergeRefusesToWriteOverItsInput) {
  TemporaryDirectory dir("fibremss_merge_over");
  const fs::path run = dir.path() / "run";
  fs::create_directories(run);
  writeFile(run / "summary.json", kSummary);
  for (const std::string& input : {run.string(), (run / "summary.json").string()}) {
    const ProcessResult result = cli("merge " + input + " --out " + run.string() + "/.");
    EXPECT_EQ(result.exitCode, 2) << result.output;
    EXPECT_NE(result.output.find("--out"), std::string::npos) << result.output;
    std::ifstream in(run / "summary.json");
    EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), kSummary);
  }
  EXPECT_EQ(filesIn(run), std::vector<std::string>{"summary.json"});
}

TEST(HostileInputs, MergeOfADeeplyNestedSummaryIsRefused) {
  TemporaryDirectory dir("fibremss_merge_deep");
  const size_t depth = 1000000;
  writeFile(dir.path() / "summary.json", R"({"runs": [{"method": "fibremss", "extra": )" +
                                             std::string(depth, '[') + std::string(depth, ']') +
                                             "}]}");
  const fs::path out = dir.path() / "merged";
  const ProcessResult result = cli("merge " + dir.path().string() + " --out " + out.string());
  EXPECT_EQ(result.exitCode, 2) << result.output.substr(0, 500);
  EXPECT_NE(result.output.find("nested deeper than 100 levels"), std::string::npos);
  EXPECT_FALSE(fs::exists(out));
}

TEST(HostileInputs, ATermSignalWhilePlottingEndsWith143LeavingNoPartialPlot) {
  TemporaryDirectory dir("fibremss_merge_term");
  const fs::path bin = dir.path() / "bin", run = dir.path() / "run", out = dir.path() / "merged";
  fs::create_directories(bin);
  fs::create_directories(run);
  writeFile(run / "summary.json", kSummary);
  // A gnuplot stopped by a job scheduler mid-plot: its partial plot written, then its process
  // group (the fibremss process's own, through setsid) sent SIGTERM.
  writeFile(bin / "gnuplot",
            "#!/bin/sh\ntouch \"$OUT/speed_vs_error.png.partial\"\nkill -TERM 0\nsleep 5\n");
  fs::permissions(bin / "gnuplot", fs::perms::owner_all);
  const ProcessResult result = testing::runProcess(
      "PATH=\"" + bin.string() + ":$PATH\" OUT=\"" + out.string() + "\" setsid -w \"" +
      FIBREMSS_CLI + "\" merge " + run.string() + " --out " + out.string() + " 2>&1");
  EXPECT_EQ(result.exitCode, 143) << result.output;
  EXPECT_TRUE(fs::exists(out / "summary.json")) << result.output;
  EXPECT_FALSE(fs::exists(out / "report.md"));
  for (const std::string& file : filesIn(out))
    EXPECT_EQ(file.find(".partial"), std::string::npos) << file;
}

// --- view: run.pvd ------------------------------------------------------------------------------

TEST(HostileInputs, ACollectionWithAHugeAttributeIsReadWithoutRecursion) {
  TemporaryDirectory dir("fibremss_pvd");
  const fs::path pvd = dir.path() / "run.pvd";
  writeFile(pvd,
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\">\n<Collection>\n"
            "<DataSet timestep=\"0.5\" part=\"2\" file=\"a.vtp\" note=\"" +
                std::string(50000, 'x') + "\"/>\n</Collection>\n</VTKFile>\n");
  const std::vector<PvdDataSet> sets = readPvd(pvd.string());
  ASSERT_EQ(sets.size(), 1u);
  EXPECT_EQ(sets[0].file, "a.vtp");
  EXPECT_EQ(sets[0].part, 2);
  EXPECT_EQ(sets[0].time, 0.5);
  // An unterminated tag is an error naming the line, not a scan to the end and back.
  writeFile(pvd, "<VTKFile type=\"Collection\">\n<DataSet file=\"" + std::string(50000, 'x'));
  try {
    readPvd(pvd.string());
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where(), "line 2") << e.what();
  }
}

// --- --out: a full disk, paths taken by the wrong kind -----------------------------------------

TEST(HostileInputs, AFullDiskIsABadInputNamingThePathAndLeavesNothingHalfWritten) {
  TemporaryDirectory dir("fibremss_full_disk");
  const fs::path out = dir.path() / "out";
  // A file-size limit (64 blocks) stands for the full disk: write() fails there as on a full one.
  const ProcessResult result = testing::runProcess(
      "ulimit -f 64 && trap '' XFSZ && exec \"" FIBREMSS_CLI "\" check fusiform --out " +
      out.string() + " 2>&1");
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("cannot write: File too large"), std::string::npos) << result.output;
  EXPECT_NE(result.output.find(out.string()), std::string::npos) << result.output;
  for (const std::string& file : filesIn(out))
    EXPECT_EQ(file.find(".tmp."), std::string::npos) << file;
}

TEST(HostileInputs, OutputPathsTakenByTheWrongKindAreBadInputNamingThePath) {
  TemporaryDirectory dir("fibremss_taken");
  const std::string run = "run fusiform --steps 1 --set resolution=6 --out ";
  fs::create_directories(dir.path() / "frames-file");
  writeFile(dir.path() / "frames-file" / "frames", "a file where the frames go");
  ProcessResult result = cli(run + (dir.path() / "frames-file").string());
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("frames-file/frames"), std::string::npos) << result.output;
  fs::create_directories(dir.path() / "summary-dir" / "summary.json" / "inside");
  result = cli(run + (dir.path() / "summary-dir").string());
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("summary-dir/summary.json"), std::string::npos) << result.output;
  EXPECT_TRUE(fs::exists(dir.path() / "summary-dir" / "summary.json" / "inside"));
}

// --- names -------------------------------------------------------------------------------------

TEST(HostileInputs, NamesThatAreNotUtf8OrHugeAreRefusedNamingTheFieldWritingNothing) {
  TemporaryDirectory dir("fibremss_names");
  const fs::path out = dir.path() / "out";
  const fs::path scene = writeScene(dir.path());
  ProcessResult result = cli("run " + scene.string() + " --steps 1 --out " + out.string() +
                             " --set \"muscles.0.name=$(printf 'box\\377')\"");
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("muscles[0].name: expected UTF-8 text"), std::string::npos)
      << result.output;
  EXPECT_FALSE(fs::exists(out));
  const fs::path huge =
      writeScene(dir.path(), 1, R"(, "name": ")" + std::string(200000, 'n') + '"');
  result = cli("run " + huge.string() + " --steps 1 --out " + out.string());
  EXPECT_EQ(result.exitCode, 2) << result.output.substr(0, 500);
  EXPECT_NE(result.output.find("name: expected text of at most 256 bytes"), std::string::npos)
      << result.output.substr(0, 500);
  EXPECT_LT(result.output.size(), 2000u);
  EXPECT_FALSE(fs::exists(out));
  // Any other huge text the messages quote is cut short.
  const fs::path integrator = writeScene(
      dir.path(), 1, R"(, "simulation": {"integrator": ")" + std::string(200000, 'i') + "\"}");
  result = cli("check " + integrator.string());
  EXPECT_EQ(result.exitCode, 2) << result.output.substr(0, 500);
  EXPECT_NE(result.output.find("simulation.integrator: expected one of"), std::string::npos)
      << result.output.substr(0, 500);
  EXPECT_LT(result.output.size(), 2000u);
}

// --- preparation: particles packed along few lines ----------------------------------------------

TEST(HostileInputs, ParticlesPackedAlongFewFibresAreRefusedBeforeQhull) {
  TemporaryDirectory dir("fibremss_packed");
  // 10 000 particles along 4 straight fibres 10 mm apart: 0.008 mm apart along each.
  const fs::path scene = writeScene(dir.path());
  const ProcessResult result =
      cli("check " + scene.string() + " --set muscles.0.resolution=2500 --set layout=delaunay");
  EXPECT_EQ(result.exitCode, 2) << result.output;
  EXPECT_NE(result.output.find("springs.layout: the 10000 particles lie packed along few lines"),
            std::string::npos)
      << result.output;
}

}  // namespace
}  // namespace fibremss
