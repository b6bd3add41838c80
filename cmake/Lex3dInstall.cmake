# The installed package: liblex3d.so (every module's objects, compiled once: the modules
# are position-independent, CMAKE_POSITION_INDEPENDENT_CODE), the public headers,
# lex3dConfig.cmake / lex3dConfigVersion.cmake exporting lex3d::lex3d, and lex3d.pc.
# The command and the tests keep linking the per-module static libraries.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(LEX3D_MODULES core io range features alphabet model codec residual place eval api)
set(lex3d_objects)
foreach(m IN LISTS LEX3D_MODULES)
  list(APPEND lex3d_objects $<TARGET_OBJECTS:lex3d_${m}>)
endforeach()
# The CLI executable is the target `lex3d`; the library's target is lex3d_library,
# exported as lex3d::lex3d with the file name liblex3d.so.
add_library(lex3d_library SHARED ${lex3d_objects})
add_library(lex3d::lex3d ALIAS lex3d_library)
set_target_properties(lex3d_library PROPERTIES
  OUTPUT_NAME lex3d
  EXPORT_NAME lex3d
  VERSION ${PROJECT_VERSION}
  SOVERSION ${PROJECT_VERSION_MAJOR}.${PROJECT_VERSION_MINOR})
target_include_directories(lex3d_library PUBLIC
  $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/include>
  $<BUILD_INTERFACE:${PROJECT_BINARY_DIR}/generated/include>
  $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
target_compile_features(lex3d_library PUBLIC cxx_std_17)
target_link_libraries(lex3d_library
  PUBLIC Eigen3::Eigen
  PRIVATE ZLIB::ZLIB liblzf::liblzf octomap PkgConfig::libpcap nlohmann_json::nlohmann_json lex3d_pcl
          Threads::Threads)
# Every module symbol must resolve inside the library or its dependencies (a sanitizer's
# runtime is linked by the executable instead).
if(NOT LEX3D_SANITIZE)
  target_link_options(lex3d_library PRIVATE -Wl,--no-undefined)
endif()

install(TARGETS lex3d_library EXPORT lex3dTargets
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(DIRECTORY include/lex3d DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(FILES ${PROJECT_BINARY_DIR}/generated/include/lex3d/version.hpp
  DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/lex3d)

set(LEX3D_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/lex3d)
install(EXPORT lex3dTargets NAMESPACE lex3d:: DESTINATION ${LEX3D_CMAKE_DIR})
configure_package_config_file(cmake/lex3dConfig.cmake.in ${PROJECT_BINARY_DIR}/lex3dConfig.cmake
  INSTALL_DESTINATION ${LEX3D_CMAKE_DIR})
# 0.x: a minor release may change the API, so only the same minor version is compatible.
write_basic_package_version_file(${PROJECT_BINARY_DIR}/lex3dConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/lex3dConfig.cmake ${PROJECT_BINARY_DIR}/lex3dConfigVersion.cmake
  DESTINATION ${LEX3D_CMAKE_DIR})
configure_file(cmake/lex3d.pc.in ${PROJECT_BINARY_DIR}/lex3d.pc @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/lex3d.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)
