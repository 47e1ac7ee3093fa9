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
#
# ORICF_ARCH and ORICF_CPUINFO stand for `uname -m` and /proc/cpuinfo (another machine's
# options, e.g. to cross-compile for it, and tests/test_llama_wheel.py).
LLAMA_VERSION="0.3.36"
_arch="${ORICF_ARCH:-$(uname -m)}"
# One name per architecture (Debian's and Docker's arm64 and amd64 are the kernel's aarch64
# and x86_64), so the cache key below is the same whichever way it was named.
case "$_arch" in arm64) _arch=aarch64 ;; amd64) _arch=x86_64 ;; esac
_cpuinfo="${ORICF_CPUINFO:-/proc/cpuinfo}"
# The first line of cpuinfo named $1, its words between spaces; none where it is absent
# (a container's or an emulator's cpuinfo may lack it: then the generic build).
_cpu_line() { echo " $({ grep -m1 "^$1[[:space:]]*:" "$_cpuinfo" || true; } | cut -d: -f2) "; }
CMAKE_ARGS="-DGGML_NATIVE=OFF"
case "$_arch" in
    x86_64)
        _cpu_flags=$(_cpu_line flags)
        for _pair in avx:AVX avx2:AVX2 fma:FMA f16c:F16C bmi2:BMI2 avx_vnni:AVX_VNNI \
                     avx512f:AVX512 avx512vbmi:AVX512_VBMI avx512_vnni:AVX512_VNNI \
                     avx512_bf16:AVX512_BF16; do
            [[ "$_cpu_flags" == *" ${_pair%%:*} "* ]] && CMAKE_ARGS+=" -DGGML_${_pair#*:}=ON"
        done
        ;;
    aarch64)
        # GGML's own Arm option: GGML_CPU_ARM_ARCH becomes -march= (ggml-cpu/CMakeLists.txt).
        # The kernel's feature names (the `Features` line) map to GCC's extensions; any of
        # them needs Armv8.2-A as the base. None of them: plain Armv8-A (GGML's default).
        _cpu_flags=$(_cpu_line Features)
        _tags=""
        [[ "$_cpu_flags" == *" asimddp "* ]] && _tags+="+dotprod"
        [[ "$_cpu_flags" == *" fphp "* && "$_cpu_flags" == *" asimdhp "* ]] && _tags+="+fp16"
        [[ "$_cpu_flags" == *" sve "* ]] && _tags+="+sve"
        [[ "$_cpu_flags" == *" i8mm "* ]] && _tags+="+i8mm"
        [[ "$_cpu_flags" == *" sve2 "* ]] && _tags+="+sve2"
        [[ -n "$_tags" ]] && CMAKE_ARGS+=" -DGGML_CPU_ARM_ARCH=armv8.2-a$_tags"
        ;;
    *)  # Another architecture: GGML's generic build for it, without options of this script.
        ;;
esac
export CMAKE_ARGS
# The key names the architecture too where the options alone may not (a generic Arm build
# and an x86 one without AVX both have no options); x86-64's key stays the options' alone,
# so its wheels cached before are taken as they are.
_key="$LLAMA_VERSION $CMAKE_ARGS"
case "$_arch" in x86_64) ;; *) _key+=" $_arch" ;; esac
# shellcheck disable=SC2034  # read by the scripts that source this file
LLAMA_WHEELS="$CACHE/wheels/$(echo "$_key" | sha256sum | cut -c1-12)"
unset _arch _cpuinfo _cpu_flags _pair _tags _key
unset -f _cpu_line
