# shellcheck shell=bash
# Sourced by scripts/setup.sh and compose/prepare-build.sh: which llama-cpp-python wheel fits
# this CPU. Sets LLAMA_VERSION, CMAKE_ARGS (exported, read by the build) and LLAMA_WHEELS,
# the cache folder of wheels built with those options ($CACHE/wheels/<key>; CACHE must be set).
#
# llama.cpp is built for this CPU's instruction sets, named one by one from /proc/cpuinfo
# rather than -march=native: native turns AMX on where the CPU has it, and AMX code crashes
# the process where the kernel does not grant it AMX state (many virtual machines). The
# cache folder is keyed by the build options, so another CPU type builds its own wheel, and
# a wheel built with other options is never taken (an image given one crashed on load).
LLAMA_VERSION="0.3.36"
_cpu_flags=" $(grep -m1 '^flags' /proc/cpuinfo | cut -d: -f2) "
CMAKE_ARGS="-DGGML_NATIVE=OFF"
for _pair in avx:AVX avx2:AVX2 fma:FMA f16c:F16C bmi2:BMI2 avx_vnni:AVX_VNNI avx512f:AVX512 \
             avx512vbmi:AVX512_VBMI avx512_vnni:AVX512_VNNI avx512_bf16:AVX512_BF16; do
    [[ "$_cpu_flags" == *" ${_pair%%:*} "* ]] && CMAKE_ARGS+=" -DGGML_${_pair#*:}=ON"
done
export CMAKE_ARGS
# shellcheck disable=SC2034  # read by the scripts that source this file
LLAMA_WHEELS="$CACHE/wheels/$(echo "$LLAMA_VERSION $CMAKE_ARGS" | sha256sum | cut -c1-12)"
unset _cpu_flags _pair
