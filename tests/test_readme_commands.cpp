// The docs check. README.md stays a first screen (at most 200 lines), keeps the two commands a
// newcomer and CI run, and links every docs/ page. Every relative link in README.md and docs/*.md
// leads to a file of the repository, and to a heading there where it names one. Every command
// line in their code blocks that runs one of our binaries uses only options that the binary's
// --help lists. The pages are read from the source tree and the binaries run from this build, so
// a renamed option, page or heading fails here instead of in a newcomer's terminal.
#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cctype>
#include <cstddef>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "bench/child_process.hpp"
#include "support/test_support.hpp"

namespace fs = std::filesystem;

namespace {

const fs::path kSourceDir{PANDARCAP_SOURCE_DIR};

constexpr std::string_view kDemoCommand =
    "./.ci/install-deps && cmake --workflow --preset release && build/release/bin/pandarcapd "
    "--simulate --duration 2 --output-dir pandarcap-demo --allow-root";
constexpr std::string_view kTestCommand = "./.ci/install-deps && cmake --workflow --preset test";

std::string read_text(const fs::path& file) {
  INFO(file.string());
  REQUIRE(fs::is_regular_file(file));
  return pandarcap::harness::read_file(file);
}

std::vector<std::string> split_lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);)
    lines.push_back(line);
  return lines;
}

bool starts_with(std::string_view s, std::string_view prefix) {
  return s.substr(0, prefix.size()) == prefix;
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front())))
    s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back())))
    s.remove_suffix(1);
  return s;
}

// A line that opens or closes a fenced code block (``` or ~~~, indented or not).
bool is_fence(std::string_view line) {
  const std::string_view t = trim(line);
  return starts_with(t, "```") || starts_with(t, "~~~");
}

// README.md and every page in docs/.
std::vector<fs::path> markdown_files() {
  std::vector<fs::path> files{kSourceDir / "README.md"};
  for (const auto& entry : fs::directory_iterator(kSourceDir / "docs")) {
    if (entry.is_regular_file() && entry.path().extension() == ".md") files.push_back(entry.path());
  }
  std::sort(files.begin() + 1, files.end());
  return files;
}

struct CodeLine {
  std::string text;  // continuation lines (ending in '\') joined into one
  std::size_t line = 0;
};

// The lines inside fenced code blocks.
std::vector<CodeLine> code_block_lines(const std::string& markdown) {
  std::vector<CodeLine> out;
  bool in_block = false;
  bool continued = false;
  std::size_t number = 0;
  for (const std::string& line : split_lines(markdown)) {
    ++number;
    if (is_fence(line)) {
      in_block = !in_block;
      continued = false;
      continue;
    }
    if (!in_block) continue;
    std::string_view text = trim(line);
    const bool continues = !text.empty() && text.back() == '\\';
    if (continues) text.remove_suffix(1);
    if (continued) {
      out.back().text += ' ';
      out.back().text += text;
    } else {
      out.push_back({std::string(text), number});
    }
    continued = continues;
  }
  return out;
}

// The text outside fenced code blocks, with inline code spans blanked out (a span may cross a
// line break, as in any paragraph), so that `[x](y)` inside code is not taken for a link. Line
// breaks are kept, so offsets still give line numbers.
std::string prose_of(const std::string& markdown) {
  std::string prose;
  bool in_block = false;
  for (const std::string& line : split_lines(markdown)) {
    if (is_fence(line)) in_block = !in_block;
    prose += (in_block || is_fence(line)) ? std::string() : line;
    prose += '\n';
  }
  for (std::size_t i = 0; i < prose.size();) {
    if (prose[i] != '`') {
      ++i;
      continue;
    }
    const std::size_t run = std::min(prose.find_first_not_of('`', i), prose.size()) - i;
    // The closing run has exactly the same number of backticks.
    std::size_t close = i + run;
    for (;;) {
      close = prose.find(std::string(run, '`'), close);
      if (close == std::string::npos) break;
      const std::size_t len = std::min(prose.find_first_not_of('`', close), prose.size()) - close;
      if (len == run) break;
      close += len;
    }
    if (close == std::string::npos) {  // no closing run: literal backticks
      i += run;
      continue;
    }
    for (std::size_t j = i; j < close + run; ++j) {
      if (prose[j] != '\n') prose[j] = ' ';
    }
    i = close + run;
  }
  return prose;
}

struct Link {
  std::string target;
  std::size_t line = 0;
};

// Inline links and images: [text](target) and ![alt](target).
std::vector<Link> links_in(const std::string& markdown) {
  const std::string prose = prose_of(markdown);
  std::vector<Link> links;
  for (std::size_t at = prose.find("]("); at != std::string::npos; at = prose.find("](", at + 2)) {
    const std::size_t end = prose.find_first_of(") \n", at + 2);
    if (end == std::string::npos) break;
    const auto line = static_cast<std::size_t>(std::count(prose.begin(), prose.begin() + at, '\n'));
    links.push_back({prose.substr(at + 2, end - at - 2), line + 1});
  }
  return links;
}

// GitHub's anchor for a heading: lower case, spaces to '-', punctuation dropped (letters,
// digits, '-', '_' and non-ASCII bytes kept), and "-1", "-2", ... for repeats.
std::set<std::string> heading_anchors(const std::string& markdown) {
  std::set<std::string> anchors;
  bool in_block = false;
  for (const std::string& line : split_lines(markdown)) {
    if (is_fence(line)) in_block = !in_block;
    if (in_block || !starts_with(line, "#")) continue;
    const std::size_t text_at = line.find_first_not_of('#');
    if (text_at == std::string::npos || line[text_at] != ' ') continue;
    std::string slug;
    for (const char c : trim(std::string_view(line).substr(text_at))) {
      const auto u = static_cast<unsigned char>(c);
      if (std::isalnum(u)) {
        slug += static_cast<char>(std::tolower(u));
      } else if (c == ' ') {
        slug += '-';
      } else if (c == '-' || c == '_' || u >= 0x80) {
        slug += c;
      }
    }
    std::string anchor = slug;
    for (int n = 1; anchors.count(anchor) != 0; ++n)
      anchor = slug + "-" + std::to_string(n);
    anchors.insert(anchor);
  }
  return anchors;
}

// Splits a shell line into simple commands at &&, ||, ;, | and drops a trailing # comment.
std::vector<std::vector<std::string>> simple_commands(const std::string& line) {
  std::vector<std::vector<std::string>> commands(1);
  std::istringstream in(line);
  for (std::string token; in >> token;) {
    if (token.front() == '#') break;
    if (token == "&&" || token == "||" || token == ";" || token == "|") {
      commands.emplace_back();
      continue;
    }
    commands.back().push_back(token);
  }
  return commands;
}

constexpr std::array<std::string_view, 4> kBinaries = {"pandarcapd", "pandarcap-inspect",
                                                       "pandarcap-bench", "pandarcap-ctl"};

// Our binary, when `token` names one (with or without a path: build/release/bin/pandarcapd).
std::string_view binary_named(const std::string& token) {
  const std::string name = fs::path(token).filename().string();
  for (const std::string_view binary : kBinaries) {
    if (name == binary) return binary;
  }
  return {};
}

// Whether `help` lists `option` as a whole word ("--rate" is not "--rate-limit").
bool help_lists(const std::string& help, const std::string& option) {
  const auto word = [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '-' || c == '_';
  };
  for (std::size_t at = help.find(option); at != std::string::npos;
       at = help.find(option, at + 1)) {
    const bool starts = at == 0 || !word(help[at - 1]);
    const std::size_t end = at + option.size();
    if (starts && (end == help.size() || !word(help[end]))) return true;
  }
  return false;
}

}  // namespace

TEST_CASE("README is a first screen of at most 200 lines", "[readme]") {
  const std::size_t lines = split_lines(read_text(kSourceDir / "README.md")).size();
  INFO("README.md has " << lines << " lines; move detail into a docs/ page");
  CHECK(lines <= 200);
}

TEST_CASE("README keeps the two commands verbatim and CI runs the test command", "[readme]") {
  const std::vector<std::string> readme = split_lines(read_text(kSourceDir / "README.md"));
  for (const std::string_view command : {kDemoCommand, kTestCommand}) {
    INFO("README.md must hold this line exactly: " << command);
    CHECK(std::find(readme.begin(), readme.end(), command) != readme.end());
  }
  // .ci/run is what CI runs; the README promises it runs the test command exactly as written.
  const std::vector<std::string> ci = split_lines(read_text(kSourceDir / ".ci" / "run"));
  INFO(".ci/run must hold this line exactly: " << kTestCommand);
  CHECK(std::find(ci.begin(), ci.end(), kTestCommand) != ci.end());
}

TEST_CASE("README and docs links lead to files and headings in the repository", "[readme]") {
  std::size_t checked = 0;
  for (const fs::path& page : markdown_files()) {
    for (const Link& link : links_in(read_text(page))) {
      INFO(page.lexically_relative(kSourceDir).string() << ":" << link.line << ": " << link.target);
      if (starts_with(link.target, "http://") || starts_with(link.target, "https://") ||
          starts_with(link.target, "mailto:")) {
        continue;
      }
      const std::size_t hash = link.target.find('#');
      const std::string path_part = link.target.substr(0, hash);
      const fs::path target =
          path_part.empty() ? page : (page.parent_path() / path_part).lexically_normal();
      ++checked;
      const std::string inside = target.lexically_relative(kSourceDir).string();
      CHECK_FALSE(starts_with(inside, ".."));  // a reader of the repository alone has it
      CHECK(fs::exists(target));
      if (hash != std::string::npos && target.extension() == ".md" && fs::exists(target)) {
        const std::string anchor = link.target.substr(hash + 1);
        CHECK(heading_anchors(read_text(target)).count(anchor) == 1);
      }
    }
  }
  CHECK(checked >= 10);  // the pages do link to each other: a parser that finds none is broken
}

TEST_CASE("README lists every docs page", "[readme]") {
  std::set<fs::path> linked;
  for (const Link& link : links_in(read_text(kSourceDir / "README.md"))) {
    linked.insert((kSourceDir / link.target.substr(0, link.target.find('#'))).lexically_normal());
  }
  for (const fs::path& page : markdown_files()) {
    if (page.filename() == "README.md") continue;
    INFO(page.lexically_relative(kSourceDir).string() << " is not linked from README.md");
    CHECK(linked.count(page.lexically_normal()) == 1);
  }
}

TEST_CASE("README and docs commands use only options that each binary's help lists", "[readme]") {
  // --help of each binary (and of each pandarcap-bench subcommand, which has its own), run once.
  std::map<std::string, std::string> helps;
  const auto help_of = [&](const std::string& command) -> const std::string& {
    if (const auto known = helps.find(command); known != helps.end()) return known->second;
    const auto result = pandarcap::test::run_command(command + " 2>&1");
    INFO(command << "\n" << result.out);
    CHECK(result.exit_code == 0);
    CHECK(result.out.find("--") != std::string::npos);
    return helps.emplace(command, result.out).first->second;
  };
  std::size_t readme_commands = 0;
  for (const fs::path& page : markdown_files()) {
    const std::string name = page.lexically_relative(kSourceDir).string();
    for (const CodeLine& line : code_block_lines(read_text(page))) {
      for (const std::vector<std::string>& words : simple_commands(line.text)) {
        const auto at = std::find_if(words.begin(), words.end(),
                                     [](const std::string& w) { return !binary_named(w).empty(); });
        if (at == words.end()) continue;
        const std::string binary =
            "'" + pandarcap::test::binary(std::string(binary_named(*at))).string() + "'";
        std::string help_command = binary + " --help";
        // pandarcap-bench has subcommands, each with its own options and --help; pandarcap-ctl's
        // commands share one --help, which is the same text with or without a command.
        if (binary_named(*at) == "pandarcap-bench") {
          const auto sub = at + 1;
          if (sub != words.end() && !starts_with(*sub, "-"))
            help_command = binary + " " + *sub + " --help";
        }
        const std::string& help = help_of(help_command);
        if (name == "README.md") ++readme_commands;
        for (auto w = at + 1; w != words.end(); ++w) {
          if (!starts_with(*w, "--") || w->size() <= 2) continue;
          const std::string option = w->substr(0, w->find('='));
          INFO(name << ":" << line.line << ": " << line.text << "\n"
                    << option << " is not in the output of " << help_command);
          CHECK(help_lists(help, option));
        }
      }
    }
  }
  // The README runs pandarcapd (the demo, a real sensor, a replay) and pandarcap-inspect: a
  // parser that finds fewer is broken.
  CHECK(readme_commands >= 4);
}
