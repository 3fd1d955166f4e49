"""Prints where, relative to PREFIX, this interpreter imports modules installed
under PREFIX: the first of its site directories that lies in PREFIX/lib*/ (in
the order it searches them), else its standard layout for a prefix
(lib/python3.X/site-packages), which then needs PYTHONPATH.

    python3 rcm_python_site.py PREFIX

Debian's /usr/bin/python3 with PREFIX /usr/local: lib/python3.11/dist-packages;
with /usr: lib/python3/dist-packages. python/CMakeLists.txt installs the module
there, relative to the prefix so that `cmake --install --prefix` and DESTDIR
move it. A second line says "site" or "fallback".
"""

import os
import site
import sys
import sysconfig


def main():
    prefix = os.path.normpath(os.path.abspath(sys.argv[1]))
    for directory in site.getsitepackages():
        relative = os.path.relpath(os.path.normpath(directory), prefix)
        # /usr/local/lib/... lies under /usr too, but as /usr/local's, not /usr's.
        if relative.split(os.sep)[0].startswith("lib"):
            print(relative.replace(os.sep, "/"))
            print("site")
            return 0
    standard = sysconfig.get_path("platlib", "posix_prefix", vars={"base": prefix, "platbase": prefix})
    print(os.path.relpath(standard, prefix).replace(os.sep, "/"))
    print("fallback")
    return 0


if __name__ == "__main__":
    sys.exit(main())
