# Turns kernels/${KERNEL}.cl into a C++ source holding the program text as one string, with every
# `#include "x.h"` replaced by kernels/x.h (one level, which is all the kernels use), and the
# SHA-256 of that text, which keys the on-disk program cache.
file(READ ${KERNEL_DIR}/${KERNEL}.cl source)
string(REGEX MATCHALL "#include \"[A-Za-z0-9_]+\\.h\"" includes "${source}")
foreach(line ${includes})
  string(REGEX REPLACE "#include \"([A-Za-z0-9_]+\\.h)\"" "\\1" header "${line}")
  file(READ ${KERNEL_DIR}/${header} header_text)
  string(REPLACE "${line}" "${header_text}" source "${source}")
endforeach()
string(SHA256 hash "${source}")
# Raw string literals are limited in length by some compilers; split into 8 KiB pieces.
string(LENGTH "${source}" length)
set(pieces "")
set(offset 0)
while(offset LESS length)
  string(SUBSTRING "${source}" ${offset} 8000 piece)
  string(APPEND pieces "    R\"oclvox_cl(${piece})oclvox_cl\"\n")
  math(EXPR offset "${offset} + 8000")
endwhile()
file(WRITE ${OUT}.tmp "// Generated from kernels/${KERNEL}.cl by cmake/embed_kernel.cmake. Do not edit.
#include \"kernel_sources.hpp\"
namespace oclvox::detail {
extern const KernelSource kKernel_${KERNEL};
const KernelSource kKernel_${KERNEL} = {
    \"${KERNEL}\",
${pieces}    ,
    \"${hash}\"};
}  // namespace oclvox::detail
")
file(RENAME ${OUT}.tmp ${OUT})
