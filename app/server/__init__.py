"""Running the API as a server, apart from what it answers (``app/api``).

- ``processes``      ``tactile-zsl serve`` with several API processes on one port, supervised
- ``http_protocol``  uvicorn's httptools protocol sending each response in one write
- ``logs``           how serve, its API processes and the worker log (faiss's loader quiet)
"""
