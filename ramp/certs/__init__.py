"""`ramp certs`: the robot's certificate authority and its clients' identities (SPEC 13).

Needs pyca/cryptography; nothing of the backend imports this package at run time (the server
only reads the PEM files it writes, with the standard library's `ssl`).
"""
