// lex3d: compress lidar scans with a learned alphabet of local 3D structures.

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>
#include <exception>
#include <iostream>

#include "cli_common.hpp"
#include "progress.hpp"

int main(int argc, char** argv) {
  CLI::App app{"lex3d: compact lidar scans and maps from a learned alphabet of local 3D structures"};
  app.set_version_flag("--version", std::string("lex3d ") + LEX3D_VERSION);
  app.set_help_all_flag("--help-all", "Print the help of every command and subcommand, then exit");
  // Progress of long work on stderr (apps/progress.hpp): a bar on a terminal by default.
  // Given before or after the command name (fallthrough).
  app.fallthrough();
  app.add_flag_callback("--quiet", [] { lex3d::cli::progress_mode() = lex3d::cli::ProgressMode::kQuiet; },
                        "No progress display (errors and notes are still printed)")
      ->trigger_on_parse();
  app.add_flag_callback("--progress", [] { lex3d::cli::progress_mode() = lex3d::cli::ProgressMode::kLines; },
                        "Show progress even when stderr is not a terminal: a plain line a second with the "
                        "elapsed time and the time left (for logs)")
      ->trigger_on_parse();
  app.require_subcommand(1);
  // Every option's help shows its default value (subcommands inherit this).
  app.option_defaults()->always_capture_default(true);
  lex3d::cli::register_info(app);
  lex3d::cli::register_features(app);
  lex3d::cli::register_compress(app);
  lex3d::cli::register_decompress(app);
  lex3d::cli::register_convert(app);
  lex3d::cli::register_learn(app);
  lex3d::cli::register_reconstruct(app);
  lex3d::cli::register_place(app);
  // An unknown command: name the nearest ones (edit distance) instead of CLI11's generic error.
  if (argc > 1 && argv[1][0] != '-') {
    const std::string given = argv[1];
    std::vector<std::string> names;
    for (const CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; })) names.push_back(sub->get_name());
    if (std::find(names.begin(), names.end(), given) == names.end()) {
      const auto distance = [](const std::string& a, const std::string& b) {
        std::vector<std::size_t> row(b.size() + 1);
        for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
        for (std::size_t i = 1; i <= a.size(); ++i) {
          std::size_t diag = row[0];
          row[0] = i;
          for (std::size_t j = 1; j <= b.size(); ++j) {
            const std::size_t up = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0U : 1U)});
            diag = up;
          }
        }
        return row[b.size()];
      };
      std::string best;
      std::size_t best_d = given.size() / 2 + 2;  // farther than this is no suggestion
      for (const auto& n : names) {
        const std::size_t d = n.rfind(given, 0) == 0 ? 0 : distance(given, n);
        if (d < best_d) {
          best_d = d;
          best = n;
        }
      }
      std::string all;
      for (const auto& n : names) all += (all.empty() ? "" : ", ") + n;
      std::cerr << "lex3d: unknown command '" << given << "'"
                << (best.empty() ? "; the commands are " + all : "; did you mean '" + best + "'?") << " (see --help)\n";
      return 1;
    }
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "lex3d: " << e.what() << " (see --help)\n";
    return 1;
  } catch (const lex3d::cli::CliError& e) {
    std::cerr << "lex3d: " << e.what() << "\n";
    return e.exit_code();
  } catch (const std::invalid_argument& e) {
    std::cerr << "lex3d: " << e.what() << "\n";
    return 1;
  } catch (const std::bad_alloc&) {
    // Exit 4: the input asked for more memory than there is (not an output problem).
    const std::string& file = lex3d::cli::current_file();
    std::cerr << "lex3d: " << (file.empty() ? std::string() : file + ": ") << "out of memory\n";
    return 4;
  } catch (const std::length_error&) {
    const std::string& file = lex3d::cli::current_file();
    std::cerr << "lex3d: " << (file.empty() ? std::string() : file + ": ") << "out of memory (allocation too large)\n";
    return 4;
  } catch (const std::exception& e) {
    std::cerr << "lex3d: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
