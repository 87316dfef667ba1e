# Rooms: one static library per source folder, with the rooms it may use declared as its links.
# inspect_room(<target> DIR <folder> [DEPS <room targets and libraries>...] [PRIVATE <libs>...]
#              [EXCLUDE <files of the folder that are not the library's, e.g. main.cc>...])
# builds <folder>/*.cc and <folder>/internal/*.cc and records the folder and its DEPS, so that
# cmake/check_rooms.py (the `room_check` target, part of every build) fails the build when a
# file includes a header of a room it did not declare (directly or through a declared room), or
# another room's internal/ header.
function(inspect_room target)
  cmake_parse_arguments(R "" "DIR" "DEPS;PRIVATE;EXTRA_SOURCES;EXCLUDE" ${ARGN})
  file(GLOB srcs CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/${R_DIR}/*.cc ${PROJECT_SOURCE_DIR}/${R_DIR}/internal/*.cc)
  foreach(x ${R_EXCLUDE})
    list(REMOVE_ITEM srcs ${PROJECT_SOURCE_DIR}/${R_DIR}/${x})
  endforeach()
  add_library(${target} STATIC ${srcs} ${R_EXTRA_SOURCES})
  target_include_directories(${target} PUBLIC ${PROJECT_SOURCE_DIR})
  target_link_libraries(${target} PUBLIC ${R_DEPS} PRIVATE ${R_PRIVATE})
  set(room_deps "")
  foreach(d ${R_DEPS})
    if(d MATCHES "^(core_|server_|inspection_)")
      list(APPEND room_deps ${d})
    endif()
  endforeach()
  list(JOIN room_deps "," joined)
  set_property(GLOBAL APPEND PROPERTY INSPECT_ROOMS "${target}=${R_DIR}=${joined}")
endfunction()

# A folder that groups rooms (e.g. core/): an INTERFACE library linking them all, for consumers
# that use the whole layer (tests, benches, devices). It may not be used by its own rooms.
function(inspect_room_group target)
  add_library(${target} INTERFACE)
  target_link_libraries(${target} INTERFACE ${ARGN})
  list(JOIN ARGN "," joined)
  set_property(GLOBAL APPEND PROPERTY INSPECT_ROOMS "${target}==${joined}")
endfunction()

# Called once at the end of the top-level CMakeLists.txt.
function(inspect_add_room_check)
  get_property(rooms GLOBAL PROPERTY INSPECT_ROOMS)
  set(table ${CMAKE_BINARY_DIR}/rooms.txt)
  list(JOIN rooms "\n" text)
  file(WRITE ${table} "${text}\n")
  find_package(Python3 COMPONENTS Interpreter REQUIRED)
  add_custom_target(room_check ALL
    COMMAND ${Python3_EXECUTABLE} ${PROJECT_SOURCE_DIR}/cmake/check_rooms.py ${PROJECT_SOURCE_DIR} ${table}
            ${CMAKE_BINARY_DIR}/room_check.stamp
    COMMENT "Checking includes against the rooms' declared dependencies" VERBATIM)
endfunction()
