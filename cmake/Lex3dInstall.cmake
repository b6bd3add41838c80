# The installed package: liblex3d.so (every module's objects, compiled once: the modules
# are position-independent, CMAKE_POSITION_INDEPENDENT_CODE), optionally liblex3d.a of the
# same objects (LEX3D_INSTALL_STATIC), the ROS bag plugin liblex3d_rosbag.so under
# <libdir>/lex3d/ (LEX3D_ROSBAG), the public headers, lex3dConfig.cmake /
# lex3dConfigVersion.cmake exporting lex3d::lex3d (and lex3d::lex3d_static), and lex3d.pc.
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
# What a consumer of either library gets: the public headers (and the generated version
# header) and C++17.
function(lex3d_library_interface target)
  target_include_directories(${target} PUBLIC
    $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/include>
    $<BUILD_INTERFACE:${PROJECT_BINARY_DIR}/generated/include>
    $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  target_compile_features(${target} PUBLIC cxx_std_17)
endfunction()
lex3d_library_interface(lex3d_library)
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

# liblex3d.a (lex3d::lex3d_static): the same objects archived (a few seconds), for programs
# that must not depend on liblex3d.so. Its private dependencies are in its link interface,
# found again by lex3dConfig.cmake (the pkg-config file's Libs.private).
option(LEX3D_INSTALL_STATIC "Also build and install the static library liblex3d.a (lex3d::lex3d_static)" ON)
if(LEX3D_INSTALL_STATIC)
  # PCL's common and kd-tree libraries, LZ4 (FLANN's headers call it), bzip2 and libpcap by
  # name: the config file finds them with find_library (PCL's package, FindBZip2 and
  # FindThreads cost every consumer's configure seconds), and the export holds no path of
  # this machine.
  set(LEX3D_STATIC_BY_NAME pcl_common pcl_kdtree lz4 bz2 pcap)
  foreach(lib IN LISTS LEX3D_STATIC_BY_NAME)
    find_library(LEX3D_STATIC_${lib}_LIBRARY ${lib} REQUIRED)
    if(NOT TARGET lex3d::${lib})
      add_library(lex3d::${lib} UNKNOWN IMPORTED)
      set_target_properties(lex3d::${lib} PROPERTIES IMPORTED_LOCATION ${LEX3D_STATIC_${lib}_LIBRARY})
    endif()
  endforeach()
  add_library(lex3d_static STATIC ${lex3d_objects})
  add_library(lex3d::lex3d_static ALIAS lex3d_static)
  set_target_properties(lex3d_static PROPERTIES OUTPUT_NAME lex3d EXPORT_NAME lex3d_static)
  lex3d_library_interface(lex3d_static)
  target_link_libraries(lex3d_static
    PUBLIC Eigen3::Eigen
    PRIVATE lex3d::pcl_kdtree lex3d::pcl_common octomap octomath ZLIB::ZLIB liblzf::liblzf lex3d::pcap lex3d::bz2
            lex3d::lz4 -pthread ${CMAKE_DL_LIBS})
  install(TARGETS lex3d_static EXPORT lex3dTargets ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
  set(LEX3D_PC_LIBS_PRIVATE "-lpcl_kdtree -lpcl_common -loctomap -loctomath -lz -llzf -lpcap -lbz2 -llz4 -lpthread")
  if(CMAKE_DL_LIBS)
    string(APPEND LEX3D_PC_LIBS_PRIVATE " -l${CMAKE_DL_LIBS}")
  endif()
  set(LEX3D_PC_LIBS_PRIVATE "Libs.private: ${LEX3D_PC_LIBS_PRIVATE}")
endif()

# The ROS bag plugin: io opens it on the first bag read or written (src/io/rosbag.cpp), so
# that liblex3d.so, the command and the Python module do not load the ROS libraries (and
# boost, libpython, dbus, ... through them) at start-up. Built beside the command in the
# build tree, installed in <libdir>/lex3d/ (and in the Python package, python/).
if(LEX3D_ROSBAG)
  set(LEX3D_PLUGIN_DIR ${CMAKE_INSTALL_LIBDIR}/lex3d)
  add_library(lex3d_rosbag_plugin MODULE src/io/rosbag_plugin.cpp)
  set_target_properties(lex3d_rosbag_plugin PROPERTIES
    OUTPUT_NAME lex3d_rosbag
    LIBRARY_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}
    CXX_VISIBILITY_PRESET hidden)
  target_compile_definitions(lex3d_rosbag_plugin PRIVATE LEX3D_WITH_ROSBAG)
  target_include_directories(lex3d_rosbag_plugin PRIVATE ${PROJECT_SOURCE_DIR}/src)
  target_link_libraries(lex3d_rosbag_plugin PRIVATE lex3d_rosbag)
  lex3d_set_warnings(lex3d_rosbag_plugin)
  if(NOT LEX3D_SANITIZE)
    target_link_options(lex3d_rosbag_plugin PRIVATE -Wl,--no-undefined)
  endif()
  # everything that reads bags has the plugin built
  add_dependencies(lex3d_io lex3d_rosbag_plugin)
  install(TARGETS lex3d_rosbag_plugin LIBRARY DESTINATION ${LEX3D_PLUGIN_DIR})
  # where io looks for it: from the command's directory, and the prefix's plugin directory
  file(RELATIVE_PATH lex3d_plugin_from_bindir ${CMAKE_INSTALL_FULL_BINDIR} ${CMAKE_INSTALL_FULL_LIBDIR}/lex3d)
  set_property(SOURCE src/io/rosbag.cpp APPEND PROPERTY COMPILE_DEFINITIONS
    LEX3D_ROSBAG_PLUGIN_FROM_BINDIR="${lex3d_plugin_from_bindir}"
    LEX3D_ROSBAG_PLUGIN_INSTALL_DIR="${CMAKE_INSTALL_FULL_LIBDIR}/lex3d")
endif()
install(DIRECTORY include/lex3d DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(FILES ${PROJECT_BINARY_DIR}/generated/include/lex3d/version.hpp
  DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/lex3d)

set(LEX3D_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/lex3d)
install(EXPORT lex3dTargets NAMESPACE lex3d:: DESTINATION ${LEX3D_CMAKE_DIR})
set(LEX3D_CONFIG_STATIC ${LEX3D_INSTALL_STATIC})
configure_package_config_file(cmake/lex3dConfig.cmake.in ${PROJECT_BINARY_DIR}/lex3dConfig.cmake
  INSTALL_DESTINATION ${LEX3D_CMAKE_DIR})
# 0.x: a minor release may change the API, so only the same minor version is compatible.
write_basic_package_version_file(${PROJECT_BINARY_DIR}/lex3dConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/lex3dConfig.cmake ${PROJECT_BINARY_DIR}/lex3dConfigVersion.cmake
  DESTINATION ${LEX3D_CMAKE_DIR})
configure_file(cmake/lex3d.pc.in ${PROJECT_BINARY_DIR}/lex3d.pc @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/lex3d.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)
