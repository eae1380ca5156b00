// common/atomic_file.h: temporary beside the target, rename, no temporary left on any outcome.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "inekf_semantic_mapping/common/atomic_file.h"
#include "test_data.h"

namespace fs = std::filesystem;
using namespace inekf_semantic_mapping::common;  // NOLINT: test

namespace {

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

std::vector<std::string> listDir(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) {
    names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

}  // namespace

TEST(AtomicFile, TemporaryIsBesideTheTargetAndKeepsTheExtension) {
  const std::string tmp = temporaryPathFor("/some/dir/overlay.png");
  EXPECT_EQ(fs::path(tmp).parent_path(), fs::path("/some/dir"));
  EXPECT_EQ(fs::path(tmp).extension(), ".png");
  EXPECT_NE(fs::path(tmp).filename().string().find(std::to_string(::getpid())), std::string::npos);
  EXPECT_EQ(fs::path(tmp).filename().string().rfind(".tmp.", 0), 0u);  // hidden
  EXPECT_NE(tmp, temporaryPathFor("/some/dir/overlay.png"));           // unique per call
  EXPECT_EQ(fs::path(temporaryPathFor("map.ot")).parent_path(), fs::path(""));
  EXPECT_EQ(fs::path(temporaryPathFor("map.ot")).extension(), ".ot");
}

TEST(AtomicFile, WritesTheContentAndLeavesNoTemporary) {
  const std::string dir = inekf_semantic_mapping::test::makeTempDir("atomic_file_write");
  const std::string path = dir + "/out.txt";
  writeTextAtomically(path, "first\n");
  EXPECT_EQ(readFile(path), "first\n");
  writeTextAtomically(path, "second, longer\n");  // replaces
  EXPECT_EQ(readFile(path), "second, longer\n");
  const std::string bytes("a\0b\xff", 4);
  writeBytesAtomically(dir + "/out.bin", bytes.data(), bytes.size());
  EXPECT_EQ(readFile(dir + "/out.bin"), bytes);
  writeStreamAtomically(dir + "/out.csv", [](std::ostream& out) {
    out << "x,y\n" << 1 << ',' << 2;
  });
  EXPECT_EQ(readFile(dir + "/out.csv"), "x,y\n1,2");
  writeTextAtomically(dir + "/empty.txt", "");
  EXPECT_TRUE(fs::exists(dir + "/empty.txt"));
  EXPECT_EQ(fs::file_size(dir + "/empty.txt"), 0u);
  commitFileAtomically(dir + "/img.png", [](const std::string& tmp) {
    EXPECT_EQ(fs::path(tmp).extension(), ".png");
    std::ofstream(tmp) << "png";
  });
  EXPECT_EQ(readFile(dir + "/img.png"), "png");
  EXPECT_EQ(listDir(dir),
            (std::vector<std::string>{"empty.txt", "img.png", "out.bin", "out.csv", "out.txt"}));
  fs::remove_all(dir);
}

TEST(AtomicFile, ABodyThatThrowsLeavesThePreviousFileAndNoTemporary) {
  const std::string dir = inekf_semantic_mapping::test::makeTempDir("atomic_file_throw");
  const std::string path = dir + "/keep.txt";
  writeTextAtomically(path, "previous\n");
  // The body's own exception propagates unchanged.
  EXPECT_THROW(writeStreamAtomically(path,
                                     [](std::ostream& out) {
                                       out << "half a file";
                                       throw std::logic_error("encoder failed");
                                     }),
               std::logic_error);
  EXPECT_THROW(commitFileAtomically(path,
                                    [](const std::string& tmp) {
                                      std::ofstream(tmp) << "half";
                                      throw std::runtime_error("imwrite failed");
                                    }),
               std::runtime_error);
  // A body that fails the stream without throwing is a write failure.
  try {
    writeStreamAtomically(path, [](std::ostream& out) { out.setstate(std::ios::badbit); });
    ADD_FAILURE() << "no exception";
  } catch (const AtomicWriteError& e) {
    EXPECT_NE(std::string(e.what()).find("write failed (disk full?)"), std::string::npos)
        << e.what();
    EXPECT_EQ(e.path(), path);
  }
  // A write callback that never creates the temporary fails at the rename.
  EXPECT_THROW(commitFileAtomically(path, [](const std::string&) {}), AtomicWriteError);
  EXPECT_EQ(readFile(path), "previous\n");
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"keep.txt"});
  fs::remove_all(dir);
}

// A tool's outputs appear together or not at all.
TEST(AtomicFileSet, AFailingOutputLeavesNoneOfTheSetAndNoTemporary) {
  const std::string dir = inekf_semantic_mapping::test::makeTempDir("atomic_file_set");
  writeTextAtomically(dir + "/a.txt", "old a\n");
  {
    AtomicFileSet outputs;
    outputs.addStream(dir + "/a.txt", [](std::ostream& out) { out << "new a\n"; });
    outputs.add(dir + "/b.txt", [](const std::string& tmp) { std::ofstream(tmp) << "new b\n"; });
    EXPECT_THROW(outputs.addStream(dir + "/c.txt",
                                   [](std::ostream& out) { out.setstate(std::ios::badbit); }),
                 AtomicWriteError);
  }  // never committed
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"a.txt"});
  EXPECT_EQ(readFile(dir + "/a.txt"), "old a\n");

  AtomicFileSet outputs;
  outputs.addStream(dir + "/a.txt", [](std::ostream& out) { out << "new a\n"; });
  outputs.add(dir + "/b.txt", [](const std::string& tmp) { std::ofstream(tmp) << "new b\n"; });
  EXPECT_EQ(readFile(dir + "/a.txt"), "old a\n");  // nothing visible before the commit
  outputs.commit();
  EXPECT_EQ(listDir(dir), (std::vector<std::string>{"a.txt", "b.txt"}));
  EXPECT_EQ(readFile(dir + "/a.txt"), "new a\n");
  EXPECT_EQ(readFile(dir + "/b.txt"), "new b\n");

  // A target that cannot be replaced (a directory) is refused before anything is renamed.
  fs::create_directories(dir + "/d_is_a_dir");
  {
    AtomicFileSet blocked;
    blocked.addStream(dir + "/a.txt", [](std::ostream& out) { out << "newer a\n"; });
    try {
      blocked.addStream(dir + "/d_is_a_dir", [](std::ostream& out) { out << "x"; });
      ADD_FAILURE() << "no exception";
    } catch (const AtomicWriteError& e) {
      EXPECT_EQ(e.path(), dir + "/d_is_a_dir");
    }
  }
  EXPECT_EQ(readFile(dir + "/a.txt"), "new a\n");
  EXPECT_EQ(listDir(dir), (std::vector<std::string>{"a.txt", "b.txt", "d_is_a_dir"}));

  // One file named for two outputs (inekf_offline --output-kitti X --output-truth X wrote the
  // truth over the estimate and said nothing), also spelt differently: refused, nothing written.
  {
    AtomicFileSet twice;
    twice.addStream(dir + "/a.txt", [](std::ostream& out) { out << "estimate\n"; });
    try {
      twice.addStream(dir + "/./d_is_a_dir/../a.txt", [](std::ostream& out) { out << "truth\n"; });
      ADD_FAILURE() << "no exception";
    } catch (const AtomicWriteError& e) {
      EXPECT_NE(std::string(e.what()).find("two outputs"), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(readFile(dir + "/a.txt"), "new a\n");
  EXPECT_EQ(listDir(dir), (std::vector<std::string>{"a.txt", "b.txt", "d_is_a_dir"}));
  fs::remove_all(dir);
}

// Tools check their outputs before their long work: a mistyped folder fails in a second.
TEST(AtomicFile, CheckOutputPathRefusesWhatCannotBeWritten) {
  const std::string dir = inekf_semantic_mapping::test::makeTempDir("atomic_file_check");
  EXPECT_NO_THROW(checkOutputPath(dir + "/new.txt"));
  EXPECT_FALSE(fs::exists(dir + "/new.txt"));  // checked, not created
  const auto reason = [](const std::string& path) {
    try {
      checkOutputPath(path);
    } catch (const AtomicWriteError& e) {
      EXPECT_EQ(e.path(), path);
      return e.reason();
    }
    return std::string("accepted");
  };
  EXPECT_EQ(reason(dir), "is a directory");
  EXPECT_EQ(reason(dir + "/no/such/out.txt").rfind("no directory ", 0), 0u);
  EXPECT_EQ(reason(""), "empty output path");
  try {
    checkOutputPaths({dir + "/a.txt", dir + "/b.txt", dir + "/./a.txt"});
    ADD_FAILURE() << "one file for two outputs";
  } catch (const AtomicWriteError& e) {
    EXPECT_EQ(e.path(), dir + "/./a.txt");
  }
  // An output folder may be new (its parent is there) or an existing folder; not a file, not
  // under a missing parent.
  EXPECT_NO_THROW(checkOutputDirectory(dir + "/new_folder"));
  EXPECT_NO_THROW(checkOutputDirectory(dir));
  std::ofstream(dir + "/a_file") << "x";
  EXPECT_THROW(checkOutputDirectory(dir + "/a_file"), AtomicWriteError);
  EXPECT_THROW(checkOutputDirectory(dir + "/missing/new_folder"), AtomicWriteError);
  if (::geteuid() != 0) {  // root writes anywhere
    fs::create_directories(dir + "/read_only");
    fs::permissions(dir + "/read_only", fs::perms::owner_read | fs::perms::owner_exec);
    EXPECT_NE(reason(dir + "/read_only/out.txt"), "accepted");
    fs::permissions(dir + "/read_only", fs::perms::owner_all);
  }
  fs::remove_all(dir);
}

// An output typed over an input (project_cloud --output CALIB.txt, kitti2bag --output of a file
// in the drive) replaced it with exit status 0.
TEST(AtomicFile, AnOutputThatIsAnInputIsRefused) {
  const std::string dir = inekf_semantic_mapping::test::makeTempDir("atomic_file_inputs");
  fs::create_directories(dir + "/drive/data");
  std::ofstream(dir + "/calib.txt") << "x";
  std::ofstream(dir + "/drive/data/0.txt") << "x";
  fs::create_symlink(dir + "/calib.txt", dir + "/link.txt");
  const std::vector<std::string> inputs{dir + "/calib.txt", dir + "/drive"};
  const auto reason = [&](const std::string& output) {
    try {
      checkOutputsAreNotInputs({output}, inputs);
    } catch (const AtomicWriteError& e) {
      EXPECT_EQ(e.path(), output);
      return e.reason();
    }
    return std::string("accepted");
  };
  EXPECT_EQ(reason(dir + "/calib.txt").rfind("is an input (", 0), 0u);
  EXPECT_EQ(reason(dir + "/./link.txt").rfind("is an input (", 0), 0u);  // however spelt
  EXPECT_EQ(reason(dir + "/drive/data/0.txt").rfind("is in the input folder ", 0), 0u);
  // Output folders: in an input folder, new or not (the same answer on every run).
  for (const std::string& folder :
       {dir + "/drive/data", dir + "/drive/new_folder", dir + "/drive"}) {
    EXPECT_THROW(checkOutputFolderIsNotInAnInput(folder, inputs), AtomicWriteError) << folder;
  }
  EXPECT_NO_THROW(checkOutputFolderIsNotInAnInput(dir + "/labels", inputs));
  EXPECT_EQ(reason(dir + "/drive").rfind("is an input (", 0), 0u);
  EXPECT_EQ(reason(dir + "/drive/new.txt"), "accepted");  // replaces nothing
  EXPECT_EQ(reason(dir + "/out.txt"), "accepted");
  std::ofstream(dir + "/out.txt") << "x";
  EXPECT_EQ(reason(dir + "/out.txt"), "accepted");  // an earlier output, not an input
  fs::remove_all(dir);
}

TEST(AtomicFile, AMissingDirectoryThrowsNamingThePath) {
  const std::string dir = inekf_semantic_mapping::test::makeTempDir("atomic_file_nodir");
  const std::string path = dir + "/no/such/dir/out.txt";
  try {
    writeTextAtomically(path, "x");
    ADD_FAILURE() << "no exception";
  } catch (const AtomicWriteError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("'" + path + "'"), std::string::npos) << what;
    EXPECT_NE(what.find("No such file or directory"), std::string::npos) << what;
    EXPECT_EQ(e.path(), path);
    EXPECT_EQ(what, "cannot write '" + path + "': " + e.reason());
  }
  EXPECT_THROW(writeTextAtomically("", "x"), AtomicWriteError);
  // A target that is a directory: the rename fails, the temporary is removed.
  fs::create_directories(dir + "/target_is_a_dir");
  EXPECT_THROW(writeTextAtomically(dir + "/target_is_a_dir", "x"), AtomicWriteError);
  EXPECT_EQ(listDir(dir), std::vector<std::string>{"target_is_a_dir"});
  fs::remove_all(dir);
}
