# matex — one entry point. `make` builds libmatex.a and ./matex; `make test` runs the suite.
# Variables: CC (gcc or clang), BUILD (output folder), SAN=1 (sanitizers; see `make asan`).

CC      ?= gcc
CXX     ?= g++
BUILD   ?= build
OPT     ?= -O2
SAN     ?=

WARN     = -Wall -Wextra -Werror
CFLAGS   = -std=c11 $(OPT) -g $(WARN) -pthread -D_GNU_SOURCE -ffp-contract=off -MMD -MP
CXXFLAGS = -std=c++17 $(OPT) -g $(WARN) -pthread -MMD -MP -I/usr/include/OpenEXR -I/usr/include/Imath
LDLIBS   = -lm -lpthread
# The file adapter's libraries. OpenImageIO is not among them: its part of the adapter is
# libmatex_oiio.so, opened on first use (pipeline/io/oiio_adapter.h) beside matex (build/, or
# PREFIX/bin/../lib once installed), or through the RUNPATH: the build folder for the test and
# benchmark programs, PREFIX/lib for a program linked through matex.pc.
IO_CORE_LIBS = -lOpenMeshCore -lOpenEXR -lIex -lImath -lz -lstdc++ -ldl
IOLIBS   = $(IO_CORE_LIBS) -Wl,-rpath,$(abspath $(BUILD))
OIIO_LIBS = -lOpenImageIO -lOpenImageIO_Util

SANITIZERS = address,undefined
ifeq ($(SAN),1)
CFLAGS   += -fsanitize=$(SANITIZERS) -fno-omit-frame-pointer -fno-sanitize-recover=undefined
CXXFLAGS += -fsanitize=$(SANITIZERS) -fno-omit-frame-pointer -fno-sanitize-recover=undefined
LDFLAGS  += -fsanitize=$(SANITIZERS)
endif

# CUDA=1 (set by `make cuda`): the C code knows the CUDA backend; programs link libmx_cuda.a.
ifeq ($(CUDA),1)
CFLAGS  += -DMX_WITH_CUDA
LDLIBS  += $(BUILD)/libmx_cuda.a $(BUILD)/libmx_core.a $(CUDA_LIBS)
endif
ifeq ($(SAN),fuzz)
CFLAGS   += -fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined
CXXFLAGS += -fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined
LDFLAGS  += -fsanitize=address,undefined
endif

AVX2_FLAGS   = -mavx2 -mfma -mf16c
AVX512_FLAGS = -mavx512f -mavx512bw -mavx512vl -mavx512dq -mfma -mf16c
AVX512BF16_FLAGS = $(AVX512_FLAGS) -mavx512bf16
AMX_FLAGS    = $(AVX512BF16_FLAGS) -mamx-tile -mamx-bf16

# aarch64: NEON is in every aarch64 core, so the NEON files take the baseline (armv8-a: Cortex-A53/A72
# too); the bf16 files run only where getauxval reports FEAT_BF16 (runtime/cpuid.c).
NEONBF16_FLAGS = -march=armv8.2-a+bf16

# x86-64 gets the AVX2/AVX-512 kernels, aarch64 the NEON and FEAT_BF16 ones (chosen at run time);
# other CPUs only the scalar ones (`make ARCH=none BUILD=build-noarch` builds that way here, to
# check it; `make test-arm64` cross-builds aarch64).
ARCH ?= $(shell uname -m)
X86_SIMD_SRC  = $(wildcard ops/cpu/*_avx2.c ops/cpu/*_avx512.c ops/cpu/*_avx512bf16.c ops/cpu/*_amx.c)
NEON_SIMD_SRC = $(wildcard ops/cpu/*_neon.c ops/cpu/*_neonbf16.c)
ifneq ($(filter x86_64 i686 i386,$(ARCH)),)
SIMD_SRC    = $(X86_SIMD_SRC)
GEOM_SIMD_SRC = $(wildcard pipeline/geom/*_avx2.c)
else ifneq ($(filter aarch64 arm64,$(ARCH)),)
SIMD_SRC    = $(NEON_SIMD_SRC)
GEOM_SIMD_SRC =
CFLAGS     += -DMX_NO_X86_SIMD -DMX_WITH_NEON
else
SIMD_SRC    =
GEOM_SIMD_SRC =
CFLAGS     += -DMX_NO_X86_SIMD
endif

# Modules: a test links only the modules it needs, so one module's breakage stays local.
CORE_SRC    = $(filter-out $(X86_SIMD_SRC) $(NEON_SIMD_SRC),$(wildcard runtime/*.c ops/*.c ops/cpu/*.c)) $(SIMD_SRC)
WEIGHTS_SRC = $(wildcard weights/*.c)
NN_SRC      = $(wildcard pipeline/nn/*.c)
GEOM_SRC    = $(filter-out $(wildcard pipeline/geom/*_avx2.c),$(wildcard pipeline/geom/*.c)) $(GEOM_SIMD_SRC)
TEX_SRC     = $(wildcard pipeline/texture/*.c)
# pipeline/io holds every file format: the formats in C (glTF, the exporters, file kinds, the mesh
# loader: FORMAT_SRC, part of libmatex) over the adapter to third-party libraries (IO_SRC, libmatex_io;
# OpenImageIO in libmatex_oiio.so, opened on first use) or its stand-in io_none.c (no files, no C++).
IO_ADAPTER_C = pipeline/io/io_write.c pipeline/io/png_zlib.c pipeline/io/image_files.c
FORMAT_SRC  = $(filter-out $(IO_ADAPTER_C) pipeline/io/io_none.c,$(wildcard pipeline/io/*.c))
IO_SRC      = pipeline/io/meshio.cpp pipeline/io/exrio.cpp pipeline/io/exr_read.cpp $(IO_ADAPTER_C)
OIIO_SRC    = pipeline/io/imageio.cpp
TOOL_SRC    = $(wildcard tools/matex/cmd_*.c tools/matex/cli_*.c)
# `matex serve` and `matex batch --server` (tools/matex/serve/): the full build links libmicrohttpd and
# libcurl; matex-core and the CUDA build link serve_none.c, which says the verb is not in the build.
SERVE_SRC   = $(filter-out tools/matex/serve/serve_none.c,$(wildcard tools/matex/serve/*.c))
SERVE_NONE  = $(BUILD)/tools/matex/serve/serve_none.o
# The CUDA build goes to GPU machines without libmicrohttpd (make gpu-check-pack): no server there yet.
ifeq ($(CUDA),1)
SERVE_OBJ   = $(SERVE_NONE)
SERVE_LIBS  =
else
SERVE_OBJ   = $(call obj,$(SERVE_SRC))
SERVE_LIBS  = -lmicrohttpd -lcurl
endif

obj = $(patsubst %.c,$(BUILD)/%.o,$(patsubst %.cpp,$(BUILD)/%.o,$(1)))

LIB_CORE    = $(BUILD)/libmx_core.a
LIB_WEIGHTS = $(BUILD)/libmx_weights.a
LIB_NN      = $(BUILD)/libmx_nn.a
LIB_GEOM    = $(BUILD)/libmx_geom.a
LIB_FORMATS = $(BUILD)/libmx_formats.a
LIB_TEX     = $(BUILD)/libmx_tex.a
LIB_IO      = $(BUILD)/libmatex_io.a
LIB_OIIO    = $(BUILD)/libmatex_oiio.so
LIBMATEX    = $(BUILD)/libmatex.a
LIB_MATEX_CORE = $(BUILD)/libmatex_core.a

ALL_C_OBJ = $(call obj,$(CORE_SRC) $(WEIGHTS_SRC) $(NN_SRC) $(GEOM_SRC) $(FORMAT_SRC) $(TEX_SRC))

.PHONY: all test asan bench clean cuda test-full demo install deps core test-slurm blender-addon test-blender
# Keep objects of chained rules (test and bench objects), so reruns don't rebuild them.
.SECONDARY:
all: $(LIBMATEX) $(LIB_IO) $(LIB_OIIO) matex

# a link, not a copy: matex finds libmatex_oiio.so beside its real path (/proc/self/exe)
matex: $(BUILD)/matex
	ln -sf $< $@

$(BUILD)/matex: $(call obj,tools/matex/matex.c $(TOOL_SRC)) $(SERVE_OBJ) $(LIB_TEX) $(LIB_NN) $(LIB_FORMATS) $(LIB_GEOM) \
                $(LIB_WEIGHTS) $(LIB_IO) $(LIB_CORE)
	$(CXX) $(LDFLAGS) -pthread -o $@ $^ $(IO_CORE_LIBS) $(SERVE_LIBS) $(LDLIBS)

# The OpenImageIO adapter: imageio.cpp and the status functions it reports through, position-
# independent, only its two entry points exported.
$(LIB_OIIO): $(patsubst %,$(BUILD)/%.pic.o,$(OIIO_SRC) runtime/status.c)
	$(CXX) $(LDFLAGS) -shared -o $@ $^ $(OIIO_LIBS) -lstdc++
$(BUILD)/%.cpp.pic.o: %.cpp
	@mkdir -p $(dir $@)
	$(CXX) $(CXXFLAGS) -fPIC -fvisibility=hidden -c -o $@ $<
$(BUILD)/%.c.pic.o: %.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -fPIC -fvisibility=hidden -c -o $@ $<

$(LIB_CORE):    $(call obj,$(CORE_SRC))
$(LIB_WEIGHTS): $(call obj,$(WEIGHTS_SRC))
$(LIB_NN):      $(call obj,$(NN_SRC))
$(LIB_GEOM):    $(call obj,$(GEOM_SRC))
$(LIB_FORMATS): $(call obj,$(FORMAT_SRC))
$(LIB_TEX):     $(call obj,$(TEX_SRC))
$(LIB_IO):      $(call obj,$(IO_SRC))
$(LIBMATEX):    $(ALL_C_OBJ)
# The core library: everything in C, the I/O adapter replaced by one that refuses files.
$(LIB_MATEX_CORE): $(ALL_C_OBJ) $(BUILD)/pipeline/io/io_none.o
core: $(LIB_MATEX_CORE)
$(BUILD)/%.a: | $(BUILD)/empty.o
	@mkdir -p $(dir $@)
	rm -f $@
	ar rcs $@ $^ $(if $^,,$(BUILD)/empty.o)

# What `matex --version` says of the build (runtime/version.c).
$(BUILD)/runtime/version.o: CFLAGS += -DMX_BUILD_FLAGS='"$(OPT) -ffp-contract=off"' \
                                      -DMX_BUILD_SAN='"$(if $(filter 1,$(SAN)),$(SANITIZERS),none)"'

$(BUILD)/empty.o:
	@mkdir -p $(dir $@)
	echo 'typedef int mx_empty_unit;' | $(CC) -x c -c -o $@ -

$(BUILD)/%_avx2.o: %_avx2.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(AVX2_FLAGS) -c -o $@ $<
$(BUILD)/%_avx512.o: %_avx512.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(AVX512_FLAGS) -c -o $@ $<
$(BUILD)/%_avx512bf16.o: %_avx512bf16.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(AVX512BF16_FLAGS) -c -o $@ $<
$(BUILD)/%_amx.o: %_amx.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(AMX_FLAGS) -c -o $@ $<
$(BUILD)/%_neonbf16.o: %_neonbf16.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(NEONBF16_FLAGS) -c -o $@ $<
$(BUILD)/%.o: %.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -c -o $@ $<
$(BUILD)/%.o: %.cpp
	@mkdir -p $(dir $@)
	$(CXX) $(CXXFLAGS) -c -o $@ $<

# ---- tests: tests/test_<folder>_<name>.c tests that folder (runtime, ops, weights, nn, geom, io,
# texture, tools) and links with its module and those below it ----
TEST_SRC   = $(wildcard tests/test_*.c)
TEST_BINS  = $(patsubst tests/%.c,$(BUILD)/tests/%,$(TEST_SRC))
TEST_UTIL  = $(call obj,$(wildcard tests/util_*.c))
TEST_ALL_LIBS = $(LIB_TEX) $(LIB_NN) $(LIB_FORMATS) $(LIB_GEOM) $(LIB_WEIGHTS) $(LIB_IO) $(LIB_CORE)

$(BUILD)/tests/test_runtime_%: $(BUILD)/tests/test_runtime_%.o $(TEST_UTIL) $(LIB_CORE)
	$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)
$(BUILD)/tests/test_ops_%: $(BUILD)/tests/test_ops_%.o $(TEST_UTIL) $(LIB_CORE)
	$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)
# The AMX kernels on the software emulation of their tile operations (ops/cpu/amx_tiles.h), linked
# into test_ops_kernels: their packing, tiling and edges are tested on any AVX512_BF16 CPU.
ifeq ($(SIMD_SRC),$(X86_SIMD_SRC))
$(BUILD)/tests/amx_emu.o: tests/amx_emu.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(AVX512BF16_FLAGS) -c -o $@ $<
$(BUILD)/tests/test_ops_kernels: $(BUILD)/tests/amx_emu.o
# The cuDNN path's host-side decisions (plan keys, layouts, fallback) are tested without CUDA.
$(BUILD)/tests/test_ops_cuda_plan: $(BUILD)/ops/cuda/cudnn_plan.o
endif
# test_ops_backend names each table entry's kernel by its symbol (dladdr): the symbols are exported.
$(BUILD)/tests/test_ops_backend: LDFLAGS += -rdynamic
$(BUILD)/tests/test_weights_%: $(BUILD)/tests/test_weights_%.o $(TEST_UTIL) $(LIB_WEIGHTS) $(LIB_CORE)
	$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)
$(BUILD)/tests/test_nn_%: $(BUILD)/tests/test_nn_%.o $(TEST_UTIL) $(LIB_NN) $(LIB_WEIGHTS) $(LIB_CORE)
	$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)
# The geometry tests load their meshes through pipeline/io (mesh_load.h): libmx_formats.
$(BUILD)/tests/test_geom_%: $(BUILD)/tests/test_geom_%.o $(TEST_UTIL) $(LIB_FORMATS) $(LIB_GEOM) $(LIB_IO) $(LIB_CORE)
	$(CXX) $(LDFLAGS) -pthread -o $@ $^ $(IOLIBS) $(LDLIBS)
$(BUILD)/tests/test_io_%: $(BUILD)/tests/test_io_%.o $(TEST_UTIL) $(LIB_FORMATS) $(LIB_GEOM) $(LIB_IO) $(LIB_CORE)
	$(CXX) $(LDFLAGS) -pthread -o $@ $^ $(IOLIBS) $(LDLIBS)
$(BUILD)/tests/test_texture_%: $(BUILD)/tests/test_texture_%.o $(TEST_UTIL) $(TEST_ALL_LIBS)
	$(CXX) $(LDFLAGS) -pthread -o $@ $^ $(IOLIBS) $(LDLIBS)
$(BUILD)/tests/test_tools_%: $(BUILD)/tests/test_tools_%.o $(TEST_UTIL) $(TEST_ALL_LIBS)
	$(CXX) $(LDFLAGS) -pthread -o $@ $^ $(IOLIBS) $(LDLIBS)

# Tiny random networks of the SD1.5 family for the pipeline tests and `make demo`.
DEMO_WEIGHTS = $(BUILD)/demo/demo.mxw
$(DEMO_WEIGHTS): $(BUILD)/matex tools/scripts/make_demo_weights.sh $(wildcard tests/data/demo/*) \
                 tests/data/golden/tokenizer/vocab.json tests/data/golden/tokenizer/merges.txt
	@mkdir -p $(dir $@)
	sh tools/scripts/make_demo_weights.sh $(BUILD)/matex $@

# ---- fuzzing: one harness per input surface, tests/fuzz/fuzz_<H>.c. `make test` replays its seeds and
# every crash ever found (tests/fuzz/regress/<H>) through replay_<H>; `make fuzz FUZZ_SECONDS=N` runs
# each harness N seconds under libFuzzer (clang, ASan + UBSan) in build-fuzz, FUZZ_JOBS (2) at a time ----
FUZZ_NAMES  = $(patsubst tests/fuzz/fuzz_%.c,%,$(wildcard tests/fuzz/fuzz_*.c))
FUZZ_REPLAY = $(patsubst %,$(BUILD)/tests/fuzz/replay_%,$(FUZZ_NAMES))
FUZZ_DEPS   = $(call obj,tests/fuzz/common.c tools/matex/cli_texture_opts.c tools/matex/cli_args.c tools/matex/cli_progress.c tools/matex/cli_signals.c) $(LIB_TEX) $(LIB_NN) $(LIB_FORMATS) $(LIB_GEOM) \
              $(LIB_WEIGHTS) $(LIB_IO) $(LIB_CORE)
FUZZ_SECONDS ?= 20
# the request decoding of `matex serve`: its own objects on top (no HTTP library). The links put
# the objects before the libraries, so the libraries serve the objects named here too.
$(BUILD)/tests/fuzz/replay_serve_request $(BUILD)/tests/fuzz/fuzz_serve_request: \
    $(call obj,tools/matex/serve/serve_request.c tools/matex/serve/serve_auth.c tools/matex/serve/serve_zip.c tools/matex/cli_batch_manifest.c)
$(BUILD)/tests/fuzz/replay_%: $(BUILD)/tests/fuzz/fuzz_%.o $(BUILD)/tests/fuzz/replay.o $(FUZZ_DEPS)
	$(CXX) $(LDFLAGS) -pthread -o $@ $(filter %.o,$^) $(filter-out %.o,$^) $(IOLIBS) $(LDLIBS)
$(BUILD)/tests/fuzz/fuzz_%: $(BUILD)/tests/fuzz/fuzz_%.o $(FUZZ_DEPS)
	$(CXX) $(LDFLAGS) -fsanitize=fuzzer -pthread -o $@ $(filter %.o,$^) $(filter-out %.o,$^) $(IOLIBS) $(LDLIBS)
.PHONY: fuzz fuzz-ci fuzz-run
fuzz:
	$(MAKE) BUILD=build-fuzz CC=clang CXX=clang++ SAN=fuzz OPT=-O1 fuzz-run
# CI's reproducible run: fixed seed and executions per harness, fresh corpus (tests/fuzz/run.sh)
fuzz-ci:
	$(MAKE) BUILD=build-fuzz CC=clang CXX=clang++ SAN=fuzz OPT=-O1 FUZZ_CI=1 fuzz-run
fuzz-run: $(patsubst %,$(BUILD)/tests/fuzz/fuzz_%,$(FUZZ_NAMES))
	FUZZ_CI=$(FUZZ_CI) sh tests/fuzz/run.sh $(BUILD) $(FUZZ_SECONDS) $(FUZZ_NAMES)

# ---- fault injection: a test-only matex failing the k-th allocation or write (tests/faults/fault.c);
# `make test` samples k (tests/cli_faults.sh); `make faults` tries every k on the plain build
# (leaks found by the injector's count of live blocks; ~10 min on 2 cores) and the first
# allocation of each allocation site under ASan (FAULTS_SWEEP=sites) ----
MATEX_FAULTS = $(BUILD)/tests/faults/matex_faults
FAULT_WRAP   = $(foreach f,malloc calloc realloc aligned_alloc posix_memalign strdup strndup free _Znwm _Znam,-Wl,--wrap=$(f))
$(MATEX_FAULTS): $(call obj,tools/matex/matex.c $(TOOL_SRC) $(wildcard tests/faults/*.c tests/faults/*.cpp)) $(SERVE_OBJ) \
                 $(LIB_TEX) $(LIB_NN) $(LIB_FORMATS) $(LIB_GEOM) $(LIB_WEIGHTS) $(LIB_IO) $(LIB_CORE)
	$(CXX) $(LDFLAGS) $(FAULT_WRAP) -pthread -o $@ $^ $(IOLIBS) $(SERVE_LIBS) $(LDLIBS) -ldl
.PHONY: faults faults-run
faults:
	$(MAKE) FAULTS_SWEEP=full faults-run
	$(MAKE) BUILD=build-asan SAN=1 OPT=-O1 FAULTS_SWEEP=sites faults-run
FAULTS_SWEEP ?= full
faults-run: $(MATEX_FAULTS) $(DEMO_WEIGHTS)
	$(TEST_ENV) MATEX_FAULTS_SWEEP=$(FAULTS_SWEEP) sh tests/cli_faults.sh

# The network tests run on MX_TEST_DEVICE: cpu-strict by default, so that any access to
# activation memory from outside the op layer crashes them (docs/DESIGN.md §4).
MX_TEST_DEVICE ?= cpu-strict
# Tests run two at a time (tests/run.sh): most keep one core busy.
TEST_JOBS ?= 2
TEST_ENV = BUILD=$(BUILD) MATEX=$(BUILD)/matex MATEX_DEMO_WEIGHTS=$(DEMO_WEIGHTS) MX_TEST_DEVICE=$(MX_TEST_DEVICE) \
           MATEX_TEST_JOBS=$(TEST_JOBS) \
           MATEX_UNET_ONLY_WEIGHTS=$(BUILD)/demo/demo_unet_only.mxw MATEX_FAULTS=$(MATEX_FAULTS) \
           MATEX_DEMO_FAST_WEIGHTS=$(BUILD)/demo/demo_fast.mxw \
           MATEX_MAKE_VARS="BUILD=$(BUILD) CC=$(CC) CXX=$(CXX) OPT=$(OPT) SAN=$(SAN)" \
           $(if $(SAN),LD_LIBRARY_PATH=$(abspath $(BUILD)))
# (with sanitizers, dlopen runs from their interceptor and the test programs' RUNPATH is not
# searched for libmatex_oiio.so: LD_LIBRARY_PATH is)
TEST_DEPS = all core $(TEST_BINS) $(FUZZ_REPLAY) $(MATEX_FAULTS) $(DEMO_WEIGHTS) $(BUILD)/tests/maps_at_exit.so
# Everything the suite needs, built without running it (CI builds it before two suites run side by side).
.PHONY: test-deps
test-deps: $(TEST_DEPS)
# `make demo` and `make test` set up first (the missing Debian packages: tools/scripts/deps.sh,
# silent when none is), then build and run in a second make, so nothing builds before that.
.PHONY: test-run demo-run
test:
	@sh tools/scripts/deps.sh
	@$(MAKE) --no-print-directory test-run
test-run: $(TEST_DEPS)
	$(TEST_ENV) sh tests/run.sh $(TEST_BINS) $(FUZZ_REPLAY)

# Every repository path named in the docs and the code exists (tools/scripts/check_paths.sh), and the
# counts and names docs/DESIGN.md states match the code (tools/scripts/check_docs.sh); each under a
# second; `make test` runs them as tests/cli_check_paths.sh and tests/cli_check_docs.sh.
.PHONY: check
check:
	sh tools/scripts/check_paths.sh .
	sh tools/scripts/check_docs.sh .

# tests/cli_startup.sh preloads it: the libraries a matex run mapped, read at its exit
$(BUILD)/tests/maps_at_exit.so: tests/maps_at_exit.c
	@mkdir -p $(dir $@)
	$(CC) -std=c11 -O2 $(WARN) -fPIC -shared -o $@ $<  # no sanitizer: it is preloaded before their runtime

# The SD1.5-size golden cases (weights made by the golden-v1 rule in memory): minutes, GBs.
test-full: $(TEST_DEPS)
	$(TEST_ENV) MATEX_FULL=1 sh tests/run.sh $(TEST_BINS) $(FUZZ_REPLAY)

# A one-node Slurm cluster on localhost (munged, slurmctld, slurmd; slurm-wlm and munge installed when
# missing) runs tools/slurm/matex-array.sbatch over tiny-weight jobs: submit, cancel, resume.
test-slurm: all $(DEMO_WEIGHTS)
	$(TEST_ENV) timeout 300 sh tests/slurm_cluster.sh

# `matex serve` end to end with curl as the client (tests/cli_serve.sh; Debian's curl): about a minute.
.PHONY: test-serve
test-serve: all $(DEMO_WEIGHTS)
	$(TEST_ENV) timeout 300 sh tests/cli_serve.sh

# The Blender add-on (blender/matex_texture) as the zip Blender installs; `make test-blender` installs
# it in a headless Blender (Debian's `blender`) and textures, renders, cancels (tests/blender/).
ADDON_ZIP = $(BUILD)/matex_blender.zip
$(ADDON_ZIP): $(wildcard blender/matex_texture/*.py)
	@mkdir -p $(dir $@)
	rm -f $@ && cd blender && zip -q -r -X $(abspath $@) matex_texture -x '*__pycache__*'
blender-addon: $(ADDON_ZIP)
test-blender: all $(DEMO_WEIGHTS) $(ADDON_ZIP)
	$(TEST_ENV) MATEX_ADDON_ZIP=$(ADDON_ZIP) timeout 600 sh tests/blender/run.sh

# End to end in seconds with tiny random weights (they paint noise: see README): the shipped
# Spot mesh textured into demo/spot, then a contact sheet of it from 8 sides.
DEMO_OUT = demo/spot
demo:
	@sh tools/scripts/deps.sh
	@$(MAKE) --no-print-directory demo-run
demo-run: all $(DEMO_WEIGHTS)
	rm -rf $(DEMO_OUT)
	$(BUILD)/matex texture tests/data/assets/spot/spot_triangulated.obj "a black-and-white dairy cow" \
	    --weights $(DEMO_WEIGHTS) --image-size 64 --steps 4 --quiet -o $(DEMO_OUT)
	$(BUILD)/matex render $(DEMO_OUT)/mesh.glb --views 8 --size 256 -o $(DEMO_OUT)/views
	@echo "demo: textured mesh in $(CURDIR)/$(DEMO_OUT)/ (mesh.glb, mesh.obj + mesh.mtl, texture.png, texture.exr, report.json)"
	@echo "demo: contact sheet of 8 views in $(CURDIR)/$(DEMO_OUT)/views/contact_sheet.png"

asan:
	$(MAKE) BUILD=build-asan SAN=1 OPT=-O1 test

# ---- aarch64 under emulation: the core library (no C++ adapter) and the tests that need no file
# I/O adapter, cross-built in build-arm64 and run by qemu-user on CPU models with and without
# FEAT_BF16 (tests/arm64.sh; Debian: gcc-aarch64-linux-gnu qemu-user). The tiny pipeline uses the
# demo weights made by the native matex. ----
ARM64_CC    ?= aarch64-linux-gnu-gcc
ARM64_BUILD ?= build-arm64
ARM64_TESTS  = test_runtime_basics test_ops_kernels test_ops_backend test_nn_precision test_nn_clip test_nn_clip_vision \
               test_nn_transformer test_nn_unet test_nn_controlnet test_nn_vae test_nn_taesd test_nn_pipeline \
               test_texture_threads_core test_ops_wpack
# also run on the CPU model without FEAT_BF16 (tests/arm64.sh)
ARM64_NOBF16_TESTS = test_runtime_basics test_ops_kernels test_ops_backend test_nn_precision
.PHONY: test-arm64 arm64-build
test-arm64: $(DEMO_WEIGHTS)
	$(MAKE) ARCH=aarch64 CC=$(ARM64_CC) BUILD=$(ARM64_BUILD) arm64-build
	ARM64_BUILD=$(ARM64_BUILD) ARM64_CC=$(ARM64_CC) MATEX_DEMO_WEIGHTS=$(DEMO_WEIGHTS) \
	    ARM64_NOBF16_TESTS="$(ARM64_NOBF16_TESTS)" sh tests/arm64.sh $(ARM64_TESTS)
arm64-build: core $(BUILD)/matex-core $(patsubst %,$(BUILD)/tests/%,$(ARM64_TESTS))
# matex without the file I/O adapter, C only (io_none.c): `matex --version` and the verbs on
# memory and weight files, for a cross-built core.
$(BUILD)/matex-core: $(call obj,tools/matex/matex.c $(TOOL_SRC)) $(SERVE_NONE) $(LIB_TEX) $(LIB_NN) $(LIB_FORMATS) $(LIB_GEOM) \
                     $(LIB_WEIGHTS) $(BUILD)/pipeline/io/io_none.o $(LIB_CORE)
	$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)
# A test of the public API linked with the core library (no I/O adapter, no C++).
$(BUILD)/tests/%_core: $(BUILD)/tests/%.o $(TEST_UTIL) $(LIB_MATEX_CORE)
	$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)

# The Debian 12 packages the build and the tests need (tools/scripts/packages.txt), those missing,
# non-interactively (root or sudo -n); `make demo` and `make test` run it first.
deps:
	sh tools/scripts/deps.sh

# ---- benchmarks: OpenBLAS is linked into the benchmark only ----
BENCH_SRC  = $(wildcard tools/bench/bench_*.c)
BENCH_BINS = $(patsubst tools/bench/%.c,$(BUILD)/tools/bench/%,$(BENCH_SRC))
$(BUILD)/tools/bench/bench_%: $(BUILD)/tools/bench/bench_%.o $(LIB_TEX) $(LIB_NN) $(LIB_FORMATS) $(LIB_GEOM) $(LIB_WEIGHTS) $(LIB_IO) $(LIB_CORE)
	$(CXX) $(LDFLAGS) -pthread -o $@ $^ -lopenblas $(IOLIBS) $(LDLIBS)

# The CUDA benchmark needs no file I/O adapter: it links io_none.o and runs where OpenImageIO is not.
$(BUILD)/tools/bench/bench_cuda: $(BUILD)/tools/bench/bench_cuda.o $(LIB_TEX) $(LIB_NN) $(LIB_FORMATS) $(LIB_GEOM) $(LIB_WEIGHTS) \
                           $(BUILD)/pipeline/io/io_none.o $(LIB_CORE)
	$(CC) $(LDFLAGS) -o $@ $^ $(LDLIBS)

bench: all $(BENCH_BINS)
	sh tools/bench/bench.sh $(BUILD)

PREFIX ?= /usr/local
# matex.pc: the static libraries and what they need (the I/O adapter and libmatex refer to
# each other, hence the group); not OpenImageIO: the RUNPATH ${libdir} lets the program find
# libmatex_oiio.so there when a file needs it (JPEG, TIFF ...).
PC_LIBS = -L$${libdir} -Wl,--start-group -lmatex -lmatex_io -Wl,--end-group $(IO_CORE_LIBS) $(LDLIBS) -pthread \
          -Wl,-rpath,$${libdir} $(LDFLAGS)
install: all
	install -D -m 755 $(BUILD)/matex $(DESTDIR)$(PREFIX)/bin/matex
	install -D -m 644 $(LIBMATEX) $(DESTDIR)$(PREFIX)/lib/libmatex.a
	install -D -m 644 $(LIB_IO) $(DESTDIR)$(PREFIX)/lib/libmatex_io.a
	install -D -m 755 $(LIB_OIIO) $(DESTDIR)$(PREFIX)/lib/libmatex_oiio.so
	install -D -m 644 include/matex.h $(DESTDIR)$(PREFIX)/include/matex.h
	# the CLIP vocabulary (MIT, OpenAI) for single-file checkpoints, which carry none (matex convert)
	for f in vocab.json merges.txt LICENSE; do \
	    install -D -m 644 tests/data/golden/tokenizer/$$f $(DESTDIR)$(PREFIX)/share/matex/tokenizer/$$f; done
	@mkdir -p $(DESTDIR)$(PREFIX)/lib/pkgconfig
	printf 'prefix=%s\nlibdir=$${prefix}/lib\nincludedir=$${prefix}/include\n\nName: matex\nDescription: %s\nVersion: %s\nCflags: -I$${includedir}\nLibs: %s\n' \
	    '$(PREFIX)' 'text-to-texture for 3D meshes (Make-A-Texture)' \
	    "$$(sed -n 's/^#define MATEX_VERSION "\(.*\)"/\1/p' include/matex.h)" '$(PC_LIBS)' \
	    > $(DESTDIR)$(PREFIX)/lib/pkgconfig/matex.pc

clean:
	rm -rf build build-asan build-fuzz matex

-include $(shell find $(BUILD) -name '*.d' 2>/dev/null)

# ---- CUDA backend: `make cuda` builds, in $(CUDA_BUILD), the CUDA kernels (libmx_cuda.a), their op
# test, the network tests and a matex whose --device accepts cuda (C sources with -DMX_WITH_CUDA).
# `make test-cuda` runs the op test, then every network golden and the tiny pipeline on the GPU
# against the CPU goldens (1e-2 where fp16/bf16 weights ran on tensor cores, the fp32 bounds
# elsewhere); without any GPU it prints one skip line (a GPU CUDA cannot use fails). Not part of `make` /
# `make test`. Fat binary for sm_80 and sm_90.
NVCC       ?= /usr/local/cuda/bin/nvcc
CUDA_HOME  ?= /usr/local/cuda
CUDA_BUILD ?= build-cuda
NVCC_ARCH   = -gencode arch=compute_80,code=sm_80 -gencode arch=compute_90,code=sm_90
NVCCFLAGS   = -std=c++17 -O3 $(NVCC_ARCH) -Xcompiler -Wall,-Wextra -Werror all-warnings -MMD -MP
# CUDNN=1 (the default where the toolkit has cudnn_graph.h): conv2d through cuDNN's graph API,
# loaded at run time (dlopen libcudnn.so.9, nothing linked) and used only under MATEX_CUDNN=1
# (cuda_cudnn.cu). CUDNN=0: today's path only.
CUDNN      ?= $(if $(wildcard $(CUDA_HOME)/include/cudnn_graph.h),1,0)
ifeq ($(CUDNN),1)
NVCCFLAGS  += -DMX_WITH_CUDNN
endif
CUDA_SRC    = $(wildcard ops/cuda/*.cu)
LIB_CUDA    = $(BUILD)/libmx_cuda.a
CUDA_TEST   = $(BUILD)/tests/cuda/test_cuda_ops
CUDA_LIBS   = -L$(CUDA_HOME)/lib64 -Xlinker -rpath=$(CUDA_HOME)/lib64 -lcublasLt -lcudart_static -ldl -lrt -lstdc++
CUDA_NN_TESTS = test_nn_unet test_nn_controlnet test_nn_vae test_nn_clip test_nn_pipeline test_nn_sd15 test_nn_record \
                test_nn_taesd test_nn_vae_tiled test_nn_pipeline_fast test_nn_clip_vision

$(LIB_CUDA): $(patsubst %.cu,$(BUILD)/%.o,$(CUDA_SRC)) $(BUILD)/ops/cuda/cudnn_plan.o
$(BUILD)/ops/cuda/%.o: ops/cuda/%.cu
	@mkdir -p $(dir $@)
	$(NVCC) $(NVCCFLAGS) -c -o $@ $<
$(CUDA_TEST): $(BUILD)/tests/cuda/test_cuda_ops.o $(TEST_UTIL) $(LIB_CUDA) $(LIB_CORE)
	$(NVCC) $(NVCC_ARCH) -o $@ -Xlinker --start-group $^ -Xlinker --end-group $(CUDA_LIBS) -lm -lpthread

ifeq ($(CUDA),1)
$(BUILD)/matex $(BUILD)/tools/bench/bench_cuda $(patsubst %,$(BUILD)/tests/%,$(CUDA_NN_TESTS)): \
    $(LIB_CUDA) # relinked when the kernels change
endif

.PHONY: test-cuda cuda-all cuda-run-tests gpu-check gpu-check-pack gpu-golden-pack
cuda:
	$(MAKE) BUILD=$(CUDA_BUILD) CUDA=1 cuda-all
cuda-all: $(LIB_CUDA) $(CUDA_TEST) $(BUILD)/matex $(patsubst %,$(BUILD)/tests/%,$(CUDA_NN_TESTS)) $(BUILD)/tools/bench/bench_cuda
test-cuda: cuda
	$(MAKE) BUILD=$(CUDA_BUILD) CUDA=1 cuda-run-tests
cuda-run-tests:
	$(TEST_ENV) MX_TEST_DEVICE=cuda MATEX_FULL=1 sh tests/cuda/run.sh $(CUDA_TEST) \
	    $(patsubst %,$(BUILD)/tests/%,$(CUDA_NN_TESTS))

# `make gpu-check` on a machine with a GPU: the evidence of tools/scripts/gpu_check.sh (docs/cuda-notes.md).
# `make gpu-check-pack` here first: stripped binaries (matex without libmatex_oiio.so, with the few libraries
# it needs that a GPU machine lacks, in lib/) and the small SD1.5 goldens into $(CUDA_BUILD)/gpu
# (~40 MB) and its archive gpu.tar.gz (~20 MB): the one file a device run carries (a run carries at
# most 64 MiB with the repository); gpu-check unpacks it and then builds nothing.
GPU_PACK = $(CUDA_BUILD)/gpu
MATEX_TESTDATA ?= ../shared
GPU_PACK_DATA = golden/sd15_controlnet/inputs.safetensors golden/sd15_controlnet/config.json golden/sd15_vae golden/sd15_clip
gpu-check:
	sh tools/scripts/gpu_check.sh
# The goldens too large to travel with the pack (a device call carries at most 64 MiB with the
# repository): one network test and the one golden folder it reads, per call. E.g.
#   make gpu-golden-pack GOLDEN=unet_mini TEST=test_nn_unet      (sd15_unet, sd15_controlnet: test_nn_sd15;
#   controlnet_mini: test_nn_controlnet; vae_mini: test_nn_vae; taesd: test_nn_taesd)
# then run(command="sh tools/scripts/gpu_golden.sh", carry=["build-cuda/gpu-golden.tar.gz"]).
GOLDEN ?= unet_mini
TEST ?= test_nn_unet
gpu-golden-pack: cuda
	rm -rf $(CUDA_BUILD)/gpu-golden && mkdir -p $(CUDA_BUILD)/gpu-golden/data/golden
	strip -o $(CUDA_BUILD)/gpu-golden/$(TEST) $(CUDA_BUILD)/tests/$(TEST)
	cp -r $(MATEX_TESTDATA)/golden/$(GOLDEN) $(CUDA_BUILD)/gpu-golden/data/golden/
	tar -C $(CUDA_BUILD) -czf $(CUDA_BUILD)/gpu-golden.tar.gz gpu-golden
	du -sh $(CUDA_BUILD)/gpu-golden.tar.gz
gpu-check-pack: cuda
	rm -rf $(GPU_PACK) && mkdir -p $(GPU_PACK)/tests/cuda $(GPU_PACK)/lib $(GPU_PACK)/data/golden/sd15_controlnet
	strip -o $(GPU_PACK)/matex $(CUDA_BUILD)/matex
	strip -o $(GPU_PACK)/bench_cuda $(CUDA_BUILD)/tools/bench/bench_cuda
	strip -o $(GPU_PACK)/tests/cuda/test_cuda_ops $(CUDA_BUILD)/tests/cuda/test_cuda_ops
	for t in $(CUDA_NN_TESTS); do strip -o $(GPU_PACK)/tests/$$t $(CUDA_BUILD)/tests/$$t || exit 1; done
	ldd $(CUDA_BUILD)/matex | awk '/=> \// {print $$3}' | grep -Ev '/lib(c|m|gcc_s|stdc\+\+|pthread|dl|rt)\.so|cuda' | \
	    while read -r lib; do cp -L "$$lib" $(GPU_PACK)/lib/ || exit 1; done
	for d in $(GPU_PACK_DATA); do cp -r $(MATEX_TESTDATA)/$$d $(GPU_PACK)/data/$$d || exit 1; done
	# the peer (diffusers' sources, ~4 MB): gpu_check.sh says so and goes on where it is missing
	if [ -f $(MATEX_TESTDATA)/peer/peer_diffusers.py ]; then mkdir -p $(GPU_PACK)/peer && \
	    cp $(MATEX_TESTDATA)/peer/peer_diffusers.py $(MATEX_TESTDATA)/peer/*-src.tar.gz $(GPU_PACK)/peer/; \
	    else echo "gpu-check-pack: no $(MATEX_TESTDATA)/peer: packed without the peer"; fi
	tar -C $(CUDA_BUILD) -czf $(GPU_PACK).tar.gz gpu
	du -sh $(GPU_PACK) $(GPU_PACK).tar.gz
