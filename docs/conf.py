"""Sphinx configuration: the API reference from the numpydoc docstrings, the pages in
docs/*.md (MyST), and the gallery from examples/ (sphinx-gallery, not executed here: each
example runs in the tests and writes its picture into docs/gallery)."""

project = "vtkraycast"
author = "the vtkraycast developers"
extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py", "auto_examples/*.zip"]
numpydoc_show_class_members = False
autodoc_typehints = "none"
myst_heading_anchors = 3
suppress_warnings = ["myst.xref_missing", "image.not_readable", "misc.highlighting_failure"]
sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    "gallery_dirs": "auto_examples",
    "plot_gallery": False,  # (the tests run every example; docs/gallery.md shows their pictures)
    "download_all_examples": False,
}
html_theme = "alabaster"
