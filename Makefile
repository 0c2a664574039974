# `make run` and `make test` each do the whole set-up on a fresh Debian 12
# machine: packages (scripts/install-deps.sh), configure, build.
BUILD_DIR ?= build
JOBS ?= 2
CMAKE_FLAGS ?=
COLLIDO_CUDA ?= AUTO

.PHONY: all deps configure build test run demo bench clean

all: build

deps:
	bash scripts/install-deps.sh
	bash scripts/install-web.sh

$(BUILD_DIR)/CMakeCache.txt:
	cmake -S . -B $(BUILD_DIR) -DCMAKE_BUILD_TYPE=Release -DCOLLIDO_CUDA=$(COLLIDO_CUDA) $(CMAKE_FLAGS)

configure: deps $(BUILD_DIR)/CMakeCache.txt

build: configure
	cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	cd $(BUILD_DIR) && ctest --output-on-failure --no-tests=error -j $(JOBS)

# The main job: the service on its embedded SQLite store in var/, with a demo
# job (a pour into the paper's wall1) submitted at start. It prints its URL and
# the demo account's sign-in; Ctrl-C stops it (jobs resume at the next start).
HOST ?= 127.0.0.1
PORT ?= 8080
run: build
	$(BUILD_DIR)/app/collidoscope serve --host $(HOST) --port $(PORT) --data var --web web/static --demo

# The command-line demo: detection and a pour on wall1 into results/demo/.
demo: build
	bash scripts/demo.sh $(BUILD_DIR)

bench: build
	$(BUILD_DIR)/app/collidoscope bench detect
	$(BUILD_DIR)/app/collidoscope bench run

clean:
	rm -rf $(BUILD_DIR)
