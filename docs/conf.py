"""Sphinx configuration of trackkit's documentation site.

Build it with ``python -m sphinx -W --keep-going -b html docs docs/_build/html`` (the README
gives the command; ``.ci/run`` runs it). Warnings are errors: a public name without a
docstring, a cross-reference that does not resolve, a tutorial that raises or overruns its
time budget all fail the build (``docs/_ext/trackkit_docs.py``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))
os.environ.setdefault("MPLBACKEND", "Agg")

project = "trackkit"
author = "the trackkit developers"
copyright = "2026, the trackkit developers"  # noqa: A001 (Sphinx's name)
release = version = "0.1.0"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "sphinx-mathjax-offline",  # MathJax served with the site: pages render with no network
    "myst_parser",
    "sphinx_design",
    "sphinx_gallery.gen_gallery",
    "trackkit_docs",
]

# TRACKKIT_DOCS_API_ONLY=1 builds without the gallery (a quick check of the docstrings)
if os.environ.get("TRACKKIT_DOCS_API_ONLY"):
    extensions.remove("sphinx_gallery.gen_gallery")

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "tutorials", "examples"]  # the gallery's sources: it renders them
root_doc = "index"

# cross-references: every one must resolve (nitpicky + -W); names of other libraries in
# signatures are not ours to link (there is no network to fetch their inventories)
nitpicky = True
nitpick_ignore_regex = [
    ("py:.*", r"(numpy|np|scipy|pyarrow|pa|dask|distributed|pydantic|typer|click|rich|zmq|"
     r"matplotlib|pathlib|collections|typing|datetime|concurrent|enum|io|os|numba|pymap3d|"
     r"ArrayLike|NDArray|npt|annotated_types|pydantic_core|typing_extensions|contextlib|"
     r"threading|multiprocessing|asyncio|types|abc|numbers|tomllib|json|csv)(\..*)?"),
    # type variables (a single capital) and the types of private modules in signatures
    ("py:.*", r"trackkit\.(\w+\.)*[A-Z]"),
    ("py:.*", r"(trackkit\.(\w+\.)*)?_\w+\..*"),
    # pydantic's field metadata and the array aliases of trackkit's signatures
    ("py:.*", r"(TypeAliasForwardRef|FieldInfo|AllowInfNan|Gt|Ge|Lt|Le|NoneType|Bool|Int|"
     r"Index|Float|Strict|MultipleOf|Interval|PydanticUndefined|ConfigDict)"),
    ("py:.*", r".*[\[\],].*|\d.*"),  # pieces of a subscripted annotation
    ("py:.*", r"(Array|BoolArray|IntArray|Path|Any|Callable|Iterable|Iterator|Sequence|"
     r"Mapping|Literal|Self|TypeVar|Protocol|NamedTuple|Enum|StrEnum|IntEnum|"
     r"float|int|str|bool|bytes|object|type|tuple|list|dict|set|frozenset|None|"
     r"slice|range|complex|Exception|ValueError|TypeError)"),
]

autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
# numpy's ArrayLike by its name, not the union it stands for (a screenful in a signature)
autodoc_type_aliases = {"ArrayLike": "numpy.typing.ArrayLike", "Array": "Array",
                        "BoolArray": "BoolArray", "IntArray": "IntArray"}
autodoc_preserve_defaults = True
autodoc_inherit_docstrings = False
autosummary_generate = False
add_module_names = False
python_maximum_signature_line_length = 88

myst_enable_extensions = ["dollarmath", "amsmath", "deflist", "colon_fence"]
myst_heading_anchors = 3
myst_url_schemes = ["http", "https", "mailto"]

sphinx_gallery_conf = {
    "examples_dirs": ["tutorials", "examples"],
    "gallery_dirs": ["auto_tutorials", "auto_examples"],
    "filename_pattern": r"/",  # every script runs at build time
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "matplotlib_animations": False,
    "reset_modules": ("matplotlib",),
    "show_memory": False,
    "copyfile_regex": r".*\.toml$",
    # its timing page loads scripts from CDNs; the budgets read each script's own time
    "write_computation_times": False,
}

html_theme = "pydata_sphinx_theme"
html_title = "trackkit"
html_static_path = []
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": [],
}
html_context = {"default_mode": "light"}  # a fresh browser has no stored mode to read
html_last_updated_fmt = None
html_show_sourcelink = False
html_copy_source = False
