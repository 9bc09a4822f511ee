# Zips the Blender add-on: cmake -DSRC=folder -DSTAGE=scratch -DEXE=vdbturb -DZIP=out.zip -P zip_addon.cmake
# The zip holds one folder, vdbturb_addon/, as Preferences > Add-ons > Install expects, with the path of the vdbturb
# it should run (cli.EXE_RECORD): the build tree's for build/vdbturb_addon.zip, the prefix's for the installed one.
file(REMOVE_RECURSE "${STAGE}")
file(COPY "${SRC}" DESTINATION "${STAGE}" FILES_MATCHING PATTERN "*.py" PATTERN "__pycache__" EXCLUDE)
file(WRITE "${STAGE}/vdbturb_addon/vdbturb_path.txt" "${EXE}\n")
get_filename_component(zip_dir "${ZIP}" DIRECTORY)
file(MAKE_DIRECTORY "${zip_dir}")
# Files in a fixed order with a fixed time stamp, so that a rebuild changes little more than what changed.
file(GLOB files RELATIVE "${STAGE}" "${STAGE}/vdbturb_addon/*")
list(SORT files)
execute_process(COMMAND "${CMAKE_COMMAND}" -E tar cf "${ZIP}" --format=zip "--mtime=2024-01-01 00:00:00 UTC"
  ${files} WORKING_DIRECTORY "${STAGE}" RESULT_VARIABLE failed)
if(failed)
  message(FATAL_ERROR "zipping the Blender add-on into ${ZIP} failed")
endif()
