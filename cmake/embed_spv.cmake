# Turns a SPIR-V binary IN into a C file OUT defining NAME[] and NAME_size.
file(READ ${IN} hex HEX)
string(LENGTH "${hex}" n_hex)
math(EXPR n_bytes "${n_hex} / 2")
math(EXPR rem "${n_bytes} % 4")
if(NOT rem EQUAL 0)
  message(FATAL_ERROR "${IN}: size ${n_bytes} is not a multiple of 4")
endif()
# SPIR-V words are little-endian in the file; regroup bytes into 0xDDCCBBAA words.
string(REGEX REPLACE "(..)(..)(..)(..)" "0x\\4\\3\\2\\1u," words "${hex}")
file(WRITE ${OUT} "/* Generated from ${IN}. */\n#include <stddef.h>\n#include <stdint.h>\nconst uint32_t ${NAME}[] = {${words}};\nconst size_t ${NAME}_size = ${n_bytes};\n")
