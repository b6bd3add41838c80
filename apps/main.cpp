// lex3d: compress lidar scans with a learned alphabet of local 3D structures.

#include <CLI/CLI.hpp>

#include <cstdio>
#include <exception>
#include <iostream>

#include "cli_common.hpp"

int main(int argc, char** argv) {
  CLI::App app{"lex3d: compact lidar scans and maps from a learned alphabet of local 3D structures"};
  app.set_version_flag("--version", std::string("lex3d ") + LEX3D_VERSION);
  app.require_subcommand(1);
  lex3d::cli::register_info(app);
  lex3d::cli::register_features(app);
  lex3d::cli::register_compress(app);
  lex3d::cli::register_decompress(app);
  lex3d::cli::register_convert(app);
  lex3d::cli::register_learn(app);
  lex3d::cli::register_reconstruct(app);
  lex3d::cli::register_place(app);
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
