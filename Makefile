# facegen: `make demo` and `make test` do all set-up on a fresh machine.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: setup demo test lint bench clean blender-venv node-deps voices

setup: $(STAMP)

# torch is pinned to the CPU wheel these machines carry (any other spec pulls GBs of CUDA).
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e '.[test,ray,scripts,corpus]'
	touch $(STAMP)

demo: $(STAMP)
	mkdir -p out
	$(BIN)/facegen animate examples/excellent_room.wav --text-file examples/excellent_room.txt --speaker 0 -o out/excellent_room.usda
	$(BIN)/facegen validate out/excellent_room.usda

test: $(STAMP) blender-venv node-deps voices
	$(BIN)/python -m pytest -q tests

lint: $(STAMP)
	$(BIN)/ruff check facegen tests benchmarks

bench: $(STAMP)
	$(BIN)/python benchmarks/run.py

clean:
	rm -rf $(VENV) out .pytest_cache

# Blender as a Python module for the DCC import test (tests/test_blender.py): PyPI bpy 5.0 needs
# Python 3.11 and numpy < 2, so it gets its own venv, plus the X11/GL libraries it links (apt, as root).
PYTHON311     ?= python3.11
BLENDER_VENV  ?= .venv-blender
BLENDER_STAMP := $(BLENDER_VENV)/.installed
BLENDER_LIBS  := libgl1 libx11-6 libxext6 libxfixes3 libxi6 libxkbcommon0 libxrender1 libsm6

blender-venv: $(BLENDER_STAMP)

$(BLENDER_STAMP):
	@missing=""; \
	if command -v dpkg >/dev/null 2>&1; then \
	  for p in $(BLENDER_LIBS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; fi; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing; \
	  else echo "blender-venv: install these apt packages as root:$$missing"; fi; \
	fi
	$(PYTHON311) -m venv $(BLENDER_VENV)
	$(BLENDER_VENV)/bin/pip install -q --upgrade pip
	$(BLENDER_VENV)/bin/pip install -q 'bpy==5.0.*' 'numpy<2'
	touch $@

# The Khronos glTF-Validator (npm) that `facegen validate` runs on .glb/.gltf files, pinned in
# facegen/assets/package.json and installed beside the script that drives it.
NODE_ASSETS := facegen/assets
NODE_STAMP  := $(NODE_ASSETS)/node_modules/.facegen-installed

node-deps: $(NODE_STAMP)

$(NODE_STAMP): $(NODE_ASSETS)/package.json
	cd $(NODE_ASSETS) && if [ -f package-lock.json ]; then npm ci --no-audit --no-fund --loglevel=error; \
	  else npm install --no-audit --no-fund --loglevel=error; fi
	touch $@

# Speech synthesisers besides espeak-ng for the voice corpus (facegen/synth/voices.py): Flite (its built-in
# voices) and Festival with its US English diphone and HTS voices, Debian packages (apt, as root, as the Blender
# libraries are); the tests skip an engine that is absent. Recorded speech for the tests of short telephone-band
# lines and scripts (tests/test_scripts.py): ALSA's spoken channel names and Asterisk's English prompt library (the -wav package holds the recordings; asterisk-core-sounds-en links them as sounds/en and holds their script).
VOICE_PKGS := flite festival festlex-cmu festlex-poslex festvox-kallpc16k festvox-kdlpc16k festvox-us-slt-hts \
              alsa-utils asterisk-core-sounds-en-wav asterisk-core-sounds-en

voices:
	@missing=""; \
	if command -v dpkg >/dev/null 2>&1; then \
	  for p in $(VOICE_PKGS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	elif ! command -v flite >/dev/null 2>&1 || ! command -v festival >/dev/null 2>&1; then \
	  echo "voices: no dpkg here: install the equivalents of these Debian packages: $(VOICE_PKGS)"; fi; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing; \
	  else echo "voices: install these apt packages as root:$$missing"; fi; \
	fi

# MediaPipe Face Mesh for the real-face benchmark (benchmarks/real_faces.py), never needed to animate: the
# mediapipe 0.10.14 wheel ships its face models (later releases download them at run time) and needs
# protobuf < 5, which the Ray extra of .venv does not allow, so it gets its own venv.
FACES_VENV  ?= .venv-faces
FACES_STAMP := $(FACES_VENV)/.installed

.PHONY: faces-venv
faces-venv: $(FACES_STAMP)

$(FACES_STAMP):
	$(PYTHON) -m venv $(FACES_VENV)
	$(FACES_VENV)/bin/pip install -q 'mediapipe==0.10.14'
	touch $@
