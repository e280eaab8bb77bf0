"""Tools beside the renderer, not part of it.

The accuracy-versus-time sweep (``mipray-sweep``), the subdivision comparison with
OpenSubdiv (``mipray-subdiv-compare``), generated scenes and the drivers of
``make bench-throughput``.
"""
