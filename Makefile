# SPDX-License-Identifier: MIT
# The two commands of the README:  `make demo`  and  `make test`.  Both install missing Debian packages.
BUILD  ?= build
ASAN   ?= build-asan
MESON  ?= meson
PY     ?= /usr/bin/python3

.PHONY: all deps demo test test-release test-asan bench install deb clean

all: $(BUILD)/build.ninja
	ninja -C $(BUILD)

deps:
	@bash .ci/deps.sh

$(BUILD)/build.ninja: | deps
	$(MESON) setup $(BUILD) -Dbuildtype=release -Dwerror=true -Dlong_tests=true

$(ASAN)/build.ninja: | deps
	$(MESON) setup $(ASAN) -Dbuildtype=debugoptimized -Dwerror=true -Dlong_tests=false \
	    -Db_sanitize=address,undefined -Db_lundef=false

# The main job: vafmd on the default scene (contact-silica, paced at 1x real time) on private ipc:// endpoints,
# one live force curve logged to HDF5 by the daemon, its pull-off observables, a PNG; the daemon is stopped.
DEMO ?= $(BUILD)/demo
demo: all
	MPLBACKEND=Agg $(PY) clients/python/examples/force_curve.py --spawn $(BUILD)/src/daemon/vafmd --out-dir $(DEMO)

# Every test: the optimised build at full statistics, then the sanitizer build (ASan + UBSan).
test: deps
	@$(MAKE) --no-print-directory test-release test-asan; \
	$(PY) .ci/summary.py $(BUILD) $(ASAN)

test-release: all
	-$(MESON) test -C $(BUILD) --print-errorlogs --num-processes 2

test-asan: $(ASAN)/build.ninja
	ninja -C $(ASAN)
	-ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
	    $(MESON) test -C $(ASAN) --print-errorlogs --num-processes 2 --timeout-multiplier 3

# Benchmarks (speed and work-precision reports under $(BUILD)/bench/).
bench: all
	$(MESON) test -C $(BUILD) --benchmark --verbose

# Install (meson install): `make install` into the build's prefix (default /usr/local), `make install
# PREFIX=/opt/vafm`, `make install DESTDIR=/tmp/stage` (a staged root, as packagers do). PREFIX applies to
# that install only: the build is configured for it (paths, the programs' RUNPATH), installed, then set back
# to its own prefix, even when the install fails (0.6.2 left it at PREFIX for every later install).
PREFIX ?=
install: all
ifeq ($(PREFIX),)
	$(MESON) install -C $(BUILD) $(if $(DESTDIR),--destdir $(DESTDIR),)
else
	@old=$$($(MESON) introspect --buildoptions $(BUILD) | $(PY) -c 'import json,sys; print([o["value"] for o in json.load(sys.stdin) if o["name"] == "prefix"][0])'); \
	[ -n "$$old" ] || { echo "make install: cannot read the prefix of $(BUILD)" >&2; exit 1; }; \
	echo "make install: prefix $(PREFIX) for this install (the build's is $$old)"; \
	$(MESON) configure $(BUILD) -Dprefix=$(PREFIX) && ninja -C $(BUILD) && \
	$(MESON) install -C $(BUILD) $(if $(DESTDIR),--destdir $(DESTDIR),); rc=$$?; \
	$(MESON) configure $(BUILD) -Dprefix=$$old && ninja -C $(BUILD) >/dev/null && exit $$rc
endif

# Debian packages (debian/): built from a copy of the tree in $(DEB)/vafm-VERSION, the .debs left in $(DEB),
# then lintian (its errors fail) and tests/test_deb.sh (each package's files; the extracted vafm runs).
DEB ?= $(BUILD)/deb
deb:
	@bash .ci/deps.sh --deb
	bash .ci/deb.sh $(DEB)

clean:
	rm -rf $(BUILD) $(ASAN)
