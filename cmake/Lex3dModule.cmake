# lex3d_set_warnings(target): the project's warning set.
function(lex3d_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow -Wconversion
                                           -Wno-sign-conversion)
  # GCC notes that passing 32-byte vectors by value changed ABI in GCC 4.6; the functions
  # that do are internal inline helpers, never called across a library boundary.
  if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
    target_compile_options(${target} PRIVATE -Wno-psabi)
  endif()
endfunction()

# lex3d_add_module(name SOURCES ... [PUBLIC_DEPS ...] [PRIVATE_DEPS ...])
# Adds static library lex3d_<name> with alias lex3d::<name>; public headers live
# in include/lex3d/<name>/, sources and private headers in src/<name>/.
function(lex3d_add_module name)
  cmake_parse_arguments(M "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(lex3d_${name} STATIC ${M_SOURCES})
  add_library(lex3d::${name} ALIAS lex3d_${name})
  target_include_directories(lex3d_${name}
    PUBLIC $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/include> $<INSTALL_INTERFACE:include>
    PRIVATE ${PROJECT_SOURCE_DIR}/src)
  target_link_libraries(lex3d_${name} PUBLIC ${M_PUBLIC_DEPS} PRIVATE ${M_PRIVATE_DEPS})
  # Hidden unless declared in a public header (between its `#pragma GCC visibility
  # push(default)` and `pop`): liblex3d.so exports the public API only, not the modules'
  # internals nor the PCL, FLANN and Eigen templates they instantiate.
  set_target_properties(lex3d_${name} PROPERTIES CXX_VISIBILITY_PRESET hidden)
  lex3d_set_warnings(lex3d_${name})
endfunction()
