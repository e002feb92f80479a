# rtp — top-level Makefile.  Targets: all test bench bench-build instr
# install uninstall clean asan ubsan tsan.  Honours CC, CFLAGS, LDFLAGS, PREFIX,
# DESTDIR; V=1 shows the commands; THREADS=0 leaves POSIX threads out;
# WERROR=0 drops -Werror.

CC      ?= cc
PREFIX  ?= /usr/local
DESTDIR ?=
THREADS ?= 1
WERROR  ?= 1
BUILD   ?= build

WARN = -std=c99 -pedantic -Wall -Wextra -Wshadow -Wstrict-prototypes \
       -Wmissing-prototypes -Wcast-qual -Wpointer-arith -Wvla -Wformat=2 \
       -Wundef -Wwrite-strings
# No a*b+c fused into one rounding where the CPU has FMA (-march=native):
# trace and re-evaluation must round alike, and clang fuses by default in
# plain C but not in the SSE2 intrinsics of the same sums (a light moved
# in clang -O2 -march=native once wrote other tree bits than gcc's).  gcc
# in -std=c99 does not fuse; the flag says so for both.
WARN += -ffp-contract=off
ifeq ($(WERROR),1)
WARN += -Werror
endif

CFLAGS ?= -O2 -g
PNG_CFLAGS := $(shell pkg-config --cflags libpng 2>/dev/null)
PNG_LIBS   := $(shell pkg-config --libs libpng 2>/dev/null)
ifneq ($(PNG_LIBS),)
DEFS += -DRTP_HAVE_PNG=1
endif
ifeq ($(THREADS),1)
DEFS += -DRTP_HAVE_THREADS=1
THREAD_LIBS = -lpthread
endif
OSMESA ?= 0
ifeq ($(OSMESA),1)
DEFS += -DRTP_HAVE_OSMESA=1
OSMESA_LIBS = -lOSMesa
endif

ALL_CFLAGS = $(WARN) $(CFLAGS) -D_POSIX_C_SOURCE=200809L $(DEFS) -Iinclude $(PNG_CFLAGS)
LIBS = $(PNG_LIBS) $(THREAD_LIBS) $(OSMESA_LIBS) -lm

ifeq ($(V),1)
Q =
else
Q = @
endif

LIB_SRC  = $(sort $(wildcard lib/*.c))
LIB_OBJ  = $(LIB_SRC:%.c=$(BUILD)/%.o)
LIB_PIC  = $(LIB_SRC:%.c=$(BUILD)/pic/%.o)
TEST_SRC = $(sort $(wildcard test/test_*.c))
TEST_BIN = $(TEST_SRC:%.c=$(BUILD)/%)
BENCH_SRC = $(sort $(wildcard test/bench/*.c))
BENCH_BIN = $(BENCH_SRC:test/bench/%.c=$(BUILD)/bench/%)

# A plain `make` compiles on every processor: the library is compiled twice
# (static, and PIC for librtp.so), ~50 s one file at a time on a 2-core VM.
# A -j given on the command line (or by a parent make) is kept as it is.
ifeq ($(filter -j%,$(MAKEFLAGS)),)
MAKEFLAGS += -j$(shell getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1)
endif

.PHONY: all test bench bench-build instr install uninstall clean asan ubsan tsan demo FORCE
all: $(BUILD)/librtp.a $(BUILD)/librtp.so rtp

$(BUILD)/%.o: %.c include/rtp.h $(wildcard lib/*.h)
	@mkdir -p $(dir $@)
	@$(if $(Q),echo "  CC      $<")
	$(Q)$(CC) $(ALL_CFLAGS) -c $< -o $@

$(BUILD)/pic/%.o: %.c include/rtp.h $(wildcard lib/*.h)
	@mkdir -p $(dir $@)
	$(Q)$(CC) $(ALL_CFLAGS) -fPIC -fvisibility=hidden -DRTP_BUILD_SHARED -c $< -o $@

$(BUILD)/librtp.a: $(LIB_OBJ)
	@$(if $(Q),echo "  AR      $@")
	$(Q)rm -f $@ && ar rcs $@ $^

# The shared library's soname changes whenever its ABI may: before 1.0 a
# minor version may add fields to the public structs (rtp.h), so a program
# built against 0.2 must not load 0.3, which would write a larger
# rtp_eval_stats than the program made room for: librtp.so.0.MINOR; from
# 1.0 on librtp.so.MAJOR.
VMAJOR := $(shell sed -nE 's/^\#define RTP_VERSION_MAJOR ([0-9]+).*/\1/p' include/rtp.h)
VMINOR := $(shell sed -nE 's/^\#define RTP_VERSION_MINOR ([0-9]+).*/\1/p' include/rtp.h)
SONAME := librtp.so.$(if $(filter 0,$(VMAJOR)),0.$(VMINOR),$(VMAJOR))

$(BUILD)/librtp.so: $(LIB_PIC) include/rtp.h
	@$(if $(Q),echo "  LD      $@")
	$(Q)$(CC) -shared -Wl,-soname,$(SONAME) $(LDFLAGS) $(LIB_PIC) -o $@ $(LIBS)
	$(Q)ln -sf librtp.so $(BUILD)/$(SONAME) # (its soname: a program linked here runs here)

# ./rtp is one file for every BUILD (make asan links it with ASan, for the
# CLI tests): .rtp-flavour holds how it was last linked, so that the next
# plain `make` (or `make bench`) links it again rather than keep another's.
RTP_FLAVOUR = $(BUILD) $(CC) $(CFLAGS) $(LDFLAGS) $(DEFS)
.rtp-flavour: FORCE
	@echo '$(RTP_FLAVOUR)' | cmp -s - $@ 2>/dev/null || echo '$(RTP_FLAVOUR)' > $@
FORCE:

rtp: cli/rtp.c include/rtp.h $(BUILD)/librtp.a .rtp-flavour
	@$(if $(Q),echo "  CCLD    $@")
	$(Q)$(CC) $(ALL_CFLAGS) $(LDFLAGS) cli/rtp.c $(BUILD)/librtp.a -o $@ $(LIBS)

$(BUILD)/test/%: test/%.c test/check.h $(BUILD)/librtp.a
	@mkdir -p $(dir $@)
	@$(if $(Q),echo "  CCLD    $@")
	$(Q)$(CC) $(ALL_CFLAGS) -Ilib $(LDFLAGS) $< $(BUILD)/librtp.a -o $@ $(LIBS)

$(BUILD)/bench/%: test/bench/%.c $(BUILD)/librtp.a
	@mkdir -p $(dir $@)
	@$(if $(Q),echo "  CCLD    $@")
	$(Q)$(CC) $(ALL_CFLAGS) -Ilib $(LDFLAGS) $< $(BUILD)/librtp.a -o $@ $(LIBS)

test: all $(TEST_BIN)
	$(Q)CC="$(CC)" RTP_BUILD="$(BUILD)" RTP_CFLAGS="$(CFLAGS)" RTP_LDFLAGS="$(LDFLAGS)" \
	    sh test/run.sh $(BUILD)/test

bench: all $(BENCH_BIN)
	$(Q)sh test/bench/run.sh $(BUILD)/bench

# The benchmark programs built, not run (CI: they use internal interfaces).
bench-build: all $(BENCH_BIN)

# Instructions per edit class under callgrind (valgrind; its header
# valgrind/callgrind.h comes with it): deterministic where wall-clock
# time on a shared machine is not.  Not part of test or bench.
$(BUILD)/instr/instr: test/instr/instr.c $(BUILD)/librtp.a
	@mkdir -p $(dir $@)
	@$(if $(Q),echo "  CCLD    $@")
	$(Q)$(CC) $(ALL_CFLAGS) $(LDFLAGS) $< $(BUILD)/librtp.a -o $@ $(LIBS)

instr: all $(BUILD)/instr/instr
	$(Q)sh test/instr/run.sh $(BUILD)/instr

asan:
	$(MAKE) BUILD=build-asan CFLAGS="-O1 -g -fsanitize=address -fno-omit-frame-pointer" LDFLAGS="-fsanitize=address" test

ubsan:
	$(MAKE) BUILD=build-ubsan CFLAGS="-O1 -g -fsanitize=undefined -fno-sanitize-recover=undefined" LDFLAGS="-fsanitize=undefined" test

# ThreadSanitizer over the whole suite.  Reports go to files (a CLI test
# does not check every rtp's exit status, and the status of a program that
# reported is 66 only at its end), and any file fails the target.
# test/tsan.supp holds what is not rtp's (Mesa's llvmpipe, OSMESA=1).
# TSan needs clang or gcc with libtsan: make CC=clang tsan.
TSAN_LOG = $(CURDIR)/build-tsan/tsan-report
tsan:
	@mkdir -p build-tsan && rm -f $(TSAN_LOG).*
	@TSAN_OPTIONS="halt_on_error=0 second_deadlock_stack=1 suppressions=$(CURDIR)/test/tsan.supp log_path=$(TSAN_LOG) $$TSAN_OPTIONS" \
	    $(MAKE) BUILD=build-tsan CFLAGS="-O1 -g -fsanitize=thread" LDFLAGS="-fsanitize=thread" test; \
	rc=$$?; \
	if ls $(TSAN_LOG).* >/dev/null 2>&1; then \
	    cat $(TSAN_LOG).*; echo "tsan: $$(ls $(TSAN_LOG).* | wc -l) process(es) reported races: $(TSAN_LOG).*"; exit 1; \
	fi; exit $$rc

VERSION = $(shell sed -nE 's/^\#define RTP_VERSION_(MAJOR|MINOR|PATCH) ([0-9]+).*/\2/p' include/rtp.h | paste -sd.)

install: all
	install -d $(DESTDIR)$(PREFIX)/lib/pkgconfig $(DESTDIR)$(PREFIX)/include $(DESTDIR)$(PREFIX)/bin
	sed -e 's|@PREFIX@|$(PREFIX)|' -e 's|@VERSION@|$(VERSION)|' \
	    -e 's|@REQUIRES@|$(if $(PNG_LIBS),libpng)|' -e 's|@LIBS@|$(THREAD_LIBS) $(OSMESA_LIBS) -lm|' \
	    lib/rtp.pc.in > $(DESTDIR)$(PREFIX)/lib/pkgconfig/rtp.pc
	install -m 644 $(BUILD)/librtp.a $(DESTDIR)$(PREFIX)/lib/
	install -m 755 $(BUILD)/librtp.so $(DESTDIR)$(PREFIX)/lib/$(SONAME)
	ln -sf $(SONAME) $(DESTDIR)$(PREFIX)/lib/librtp.so
	install -m 644 include/rtp.h $(DESTDIR)$(PREFIX)/include/
	install -m 755 rtp $(DESTDIR)$(PREFIX)/bin/

uninstall:
	rm -f $(DESTDIR)$(PREFIX)/lib/librtp.a $(DESTDIR)$(PREFIX)/lib/librtp.so \
	      $(DESTDIR)$(PREFIX)/lib/pkgconfig/rtp.pc \
	      $(DESTDIR)$(PREFIX)/lib/$(SONAME) $(DESTDIR)$(PREFIX)/include/rtp.h \
	      $(DESTDIR)$(PREFIX)/bin/rtp

clean:
	rm -rf build build-asan build-ubsan build-tsan build-fuzz rtp .rtp-flavour demo

# ------------------------------------------------------------------ fuzzing
# Every test/fuzz/fuzz_*.c is a libFuzzer target that, built without libFuzzer,
# has a plain main replaying files and folders (test/fuzz/replay.h).  `make test`
# builds those replay mains into $(BUILD)/fuzz/ and test/cli_fuzz_replay.sh
# replays every checked-in corpus test/fuzz/corpus/<target>/ through them.
#
# `make fuzz` builds the libFuzzer binaries (clang, ASan+UBSan) into
# build-fuzz/.  Run one from the top of the repository (inputs name files
# in test/fuzz/data/), on a scratch copy of its corpus, then check in any crash:
#   make fuzz
#   mkdir -p /tmp/nff && build-fuzz/fuzz_nff -rss_limit_mb=2048 \
#       -max_total_time=600 /tmp/nff test/fuzz/corpus/fuzz_nff
#   build-fuzz/fuzz_nff -minimize_crash=1 -runs=10000 crash-...
#   cp minimized-from-... test/fuzz/corpus/fuzz_nff/crash-<what>
# FUZZ_EXTRA adds flags (e.g. -fno-sanitize=pointer-overflow to look past a
# known NULL+0 report); FUZZ_CC picks the compiler (clang >= 6).
FUZZ_SRC = $(sort $(wildcard test/fuzz/fuzz_*.c))
FUZZ_REPLAY_BIN = $(FUZZ_SRC:test/fuzz/%.c=$(BUILD)/fuzz/%)
FUZZ_BIN = $(FUZZ_SRC:test/fuzz/%.c=build-fuzz/%)
FUZZ_CC ?= clang
FUZZ_FLAGS = -g -O1 -fno-omit-frame-pointer \
	-fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
	-DRTP_LIBFUZZER $(FUZZ_EXTRA)

.PHONY: fuzz
fuzz: $(FUZZ_BIN)

$(BUILD)/fuzz/%: test/fuzz/%.c test/fuzz/fuzz_common.h test/fuzz/fuzz_crc.h test/fuzz/replay.h $(BUILD)/librtp.a
	@mkdir -p $(dir $@)
	@$(if $(Q),echo "  CCLD    $@")
	$(Q)$(CC) $(ALL_CFLAGS) -Ilib $(LDFLAGS) $< $(BUILD)/librtp.a -o $@ $(LIBS)

build-fuzz/%: test/fuzz/%.c test/fuzz/fuzz_common.h test/fuzz/fuzz_crc.h test/fuzz/replay.h $(LIB_SRC) include/rtp.h $(wildcard lib/*.h)
	@mkdir -p $(dir $@)
	@$(if $(Q),echo "  FUZZ    $@")
	$(Q)$(FUZZ_CC) $(WARN) $(FUZZ_FLAGS) -D_POSIX_C_SOURCE=200809L $(DEFS) \
	    -Iinclude -Ilib $(PNG_CFLAGS) $< $(LIB_SRC) -o $@ $(LIBS)

test: $(FUZZ_REPLAY_BIN)

# make demo: the paper's sequence (Santos, figures 3, 4 and 6) on the
# project's teapot, with each step's time and its error against a full
# trace of the same edited scene.  Images go to demo/.
DEMO_SCENE ?= scenes/teapot.nff
DEMO_SIZE ?= 512x512
demo: all
	@mkdir -p demo
	@if [ ! -f ../shared/scenes/meshes/newell-teapot.bpt ]; then \
	    echo "demo: ../shared/scenes (Newell's teapot patches) is absent; using scenes/spheres.nff"; \
	    scene=scenes/spheres.nff; fig4="--set light.fill.color=1,0.6,0.3 --set mat.red.ks=0.6"; \
	    move="--set light.key.pos=4,-6,7"; \
	else scene=$(DEMO_SCENE); \
	    fig4="--set light.lamp.on=1 --set mat.table.color2=0.15,0.1,0.05 --set mat.teapot.ks=0.6"; \
	    move="--set light.key.pos=-6,-9,9"; fi; \
	j=$$(nproc 2>/dev/null || echo 2); \
	printf '%-44s %10s %12s %12s %10s\n' step seconds "full trace" speed-up "max error"; \
	./rtp trace $$scene --size $(DEMO_SIZE) -j $$j -o demo/teapot.rtp -i demo/fig3.png --stats demo/fig3.json -q && \
	printf '%-44s %10s\n' "fig. 3: first trace, trees recorded" \
	    "$$(sed -nE 's/.*"seconds": ([0-9.]+).*/\1/p' demo/fig3.json)"; \
	for step in "fig4|fig. 4: lamp on, checkerboard, shinier pot|$$fig4" \
	            "fig6|fig. 6: and the key light moved (exact)|$$fig4 $$move" \
	            "fig6i|fig. 6: light moved, item-buffer shadows|$$fig4 $$move --shadows itembuf:512"; do \
	    name=$${step%%|*}; rest=$${step#*|}; label=$${rest%%|*}; args=$${rest#*|}; \
	    ./rtp reeval demo/teapot.rtp $$args -j $$j --reference -i demo/$$name.png --stats demo/$$name.json -q || exit 1; \
	    j1=$$(cat demo/$$name.json); \
	    printf '%-44s %10s %12s %11sx %10s\n' "$$label" \
	        "$$(echo "$$j1" | sed -nE 's/.*"seconds": ([0-9.]+).*/\1/p')" \
	        "$$(echo "$$j1" | sed -nE 's/.*"reference_seconds": ([0-9.]+).*/\1/p')" \
	        "$$(echo "$$j1" | sed -nE 's/.*"speedup": ([0-9.]+).*/\1/p')" \
	        "$$(echo "$$j1" | sed -nE 's/.*"max_abs": ("?[0-9.e+-]+"?).*/\1/p')"; \
	done; \
	echo "images: demo/fig3.png demo/fig4.png demo/fig6.png demo/fig6i.png"
