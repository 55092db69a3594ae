"""Start-up hook for ParaView 5.11 on Python >= 3.11 (e.g. Debian 12's ``paraview``).

Copy this file as ``usercustomize.py`` into the directory that holds vtkraycast for
ParaView (the one on ``PYTHONPATH``); Python imports it when it starts (``site``), before
ParaView loads any Python plugin.

ParaView 5.11's Python-plugin loader (``paraview/detail/pythonalgorithm.py``) does
``from inspect import getargspec``; Python 3.11 removed ``getargspec``, so every Python
plugin fails to load with "Failed to import `paraview.detail.pythonalgorithm`" before the
plugin's own code runs. The loader only reads ``.args`` of the result, which
``getfullargspec`` also has. Nothing changes where ``getargspec`` still exists.
"""

import inspect

if not hasattr(inspect, "getargspec"):
    inspect.getargspec = inspect.getfullargspec
