# ctest driver: install the build tree to a prefix, configure and build the consumer against it, run it.
foreach(v BUILD_DIR SOURCE_DIR WORK_DIR)
  if(NOT DEFINED ${v})
    message(FATAL_ERROR "${v} not set")
  endif()
endforeach()
file(REMOVE_RECURSE "${WORK_DIR}")
execute_process(COMMAND ${CMAKE_COMMAND} --install "${BUILD_DIR}" --prefix "${WORK_DIR}/prefix"
  RESULT_VARIABLE rc OUTPUT_QUIET)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "install failed (${rc})")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} -S "${SOURCE_DIR}" -B "${WORK_DIR}/build"
  -DCMAKE_PREFIX_PATH=${WORK_DIR}/prefix -DCMAKE_BUILD_TYPE=Release RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "consumer configure failed (${rc})")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build "${WORK_DIR}/build" RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "consumer build failed (${rc})")
endif()
execute_process(COMMAND "${WORK_DIR}/build/consumer" RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "consumer run failed (${rc})")
endif()
# Farm nodes run the installed binary straight from the prefix: it must find libturb*.so through its RPATH,
# with no LD_LIBRARY_PATH, and do real work (simulate two frames and read them back).
set(exe "${WORK_DIR}/prefix/bin/vdbturb")
if(NOT EXISTS "${exe}")
  message(FATAL_ERROR "install gave no ${exe}")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} -E env --unset=LD_LIBRARY_PATH "${exe}" sim plume --res 8x8x12 --frames 2 -q
  --out "${WORK_DIR}/sim/plume.####.vdb" RESULT_VARIABLE rc ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "installed vdbturb sim failed (${rc}): ${err}")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} -E env --unset=LD_LIBRARY_PATH "${exe}" info "${WORK_DIR}/sim/plume.0002.vdb"
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0 OR NOT out MATCHES "density")
  message(FATAL_ERROR "installed vdbturb info failed (${rc}): ${out}${err}")
endif()
# The installed share/vdbturb: the demo, the docs and animate's stroke designs, which the installed binary's
# built-ins read from there (never from the source tree), run from a directory outside both trees.
foreach(f share/vdbturb/demo.sh share/vdbturb/README.md share/vdbturb/docs/transfer.md
    share/vdbturb/animate/river_strokes.json)
  if(NOT EXISTS "${WORK_DIR}/prefix/${f}")
    message(FATAL_ERROR "install gave no ${f}")
  endif()
endforeach()
execute_process(COMMAND ${CMAKE_COMMAND} -E env --unset=LD_LIBRARY_PATH "${exe}" animate
  --example builtin:river:48x40x20 --target builtin:river:48x40 --flow-strokes builtin:river
  --out "${WORK_DIR}/anim/river.####.png" -q
  WORKING_DIRECTORY "${WORK_DIR}" RESULT_VARIABLE rc ERROR_VARIABLE err)
if(NOT rc EQUAL 0 OR NOT EXISTS "${WORK_DIR}/anim/river.0001.png")
  message(FATAL_ERROR "installed vdbturb animate --flow-strokes builtin:river failed (${rc}): ${err}")
endif()
# The installed Blender add-on zip (docs/blender_addon.md) runs the installed vdbturb, not the build tree's: the path
# it records is the prefix's. (tests/blender/test_addon.py runs it in Blender from the build tree.)
set(zip "${WORK_DIR}/prefix/share/vdbturb/vdbturb_addon.zip")
if(NOT EXISTS "${zip}")
  message(FATAL_ERROR "install gave no ${zip}")
endif()
file(MAKE_DIRECTORY "${WORK_DIR}/addon")
execute_process(COMMAND ${CMAKE_COMMAND} -E tar xf "${zip}" WORKING_DIRECTORY "${WORK_DIR}/addon" RESULT_VARIABLE rc)
if(NOT rc EQUAL 0 OR NOT EXISTS "${WORK_DIR}/addon/vdbturb_addon/__init__.py")
  message(FATAL_ERROR "the installed add-on zip does not unpack to vdbturb_addon/__init__.py (${rc})")
endif()
file(READ "${WORK_DIR}/addon/vdbturb_addon/vdbturb_path.txt" recorded)
string(STRIP "${recorded}" recorded)
if(NOT recorded STREQUAL exe)
  message(FATAL_ERROR "the installed add-on runs '${recorded}', not the installed '${exe}'")
endif()
