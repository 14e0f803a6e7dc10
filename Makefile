# Set-up and everyday commands.  Both targets create .venv and install what they need.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DOCS_STAMP := $(VENV)/.installed-docs

# make test-blender: Blender 5.0.1 as the bpy module (Python 3.11, about 820 MB) in its own venv
PYTHON311 ?= python3.11
BLENDER_VENV := .venv-blender
BLENDER_STAMP := $(BLENDER_VENV)/.installed

.PHONY: demo docs test test-slow test-blender blender-addon bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

# the site's tools (mkdocs-material, mkdocstrings, mkdocs-jupyter): make test builds the site too
$(DOCS_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[docs]'
	touch $(DOCS_STAMP)

demo: $(STAMP)
	$(BIN)/casadi-keyframe solve cloth_shapes --out results/cloth_shapes --stop method

test: $(STAMP) $(DOCS_STAMP)
	$(BIN)/python -m pytest -q

# the documentation site into site/, warnings as errors; it never runs a solve (the gallery's
# pictures and figures are files, docs/gallery.py collects them from results/)
docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict --site-dir site

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow

$(BLENDER_STAMP):
	$(PYTHON311) -m venv $(BLENDER_VENV)
	$(BLENDER_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(BLENDER_VENV)/bin/python -m pip install --quiet bpy==5.0.1
	touch $(BLENDER_STAMP)

# round trips through a real Blender and the add-on run headless; not part of 'make test'
test-blender: $(STAMP) $(BLENDER_STAMP)
	BLENDER_PYTHON=$(CURDIR)/$(BLENDER_VENV)/bin/python $(BIN)/python -m pytest -q \
	    -p no:cacheprovider blender/tests

# the add-on as Blender installs it (Edit > Preferences > Add-ons > Install from Disk)
blender-addon:
	mkdir -p dist
	cd blender && $(PYTHON) -c "import pathlib, zipfile; z = zipfile.ZipFile('../dist/casadi_keyframe_blender.zip', 'w'); [z.write(p) for p in sorted(pathlib.Path('casadi_keyframe_blender').glob('*')) if p.suffix in ('.py', '.toml')]; z.close()"

bench: $(STAMP)
	$(BIN)/python benchmarks/flock_gradient.py
	$(BIN)/python benchmarks/cloth_gradient.py

clean:
	rm -rf $(VENV) $(BLENDER_VENV) results dist site .pytest_cache
