# `make run` and `make test` each do the whole set-up on a fresh Debian 12
# machine: packages (scripts/install-deps.sh), configure, build.
BUILD_DIR ?= build
JOBS ?= 2
CMAKE_FLAGS ?=
COLLIDO_CUDA ?= AUTO

.PHONY: all deps configure build test run bench clean

all: build

deps:
	bash scripts/install-deps.sh

$(BUILD_DIR)/CMakeCache.txt:
	cmake -S . -B $(BUILD_DIR) -DCMAKE_BUILD_TYPE=Release -DCOLLIDO_CUDA=$(COLLIDO_CUDA) $(CMAKE_FLAGS)

configure: deps $(BUILD_DIR)/CMakeCache.txt

build: configure
	cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS)

# The main job until the service exists: detection and a pour simulation on the
# paper's wall1, results (contacts, statistics, video) in results/demo/.
run: build
	bash scripts/demo.sh $(BUILD_DIR)

bench: build
	$(BUILD_DIR)/app/collidoscope bench detect
	$(BUILD_DIR)/app/collidoscope bench run

clean:
	rm -rf $(BUILD_DIR)
