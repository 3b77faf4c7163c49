# tactile-zsl serve: API + in-process retraining worker, SQLite under /data.
#   docker build -t tactile-zsl .
#   docker run -p 8000:8000 -v tactile-data:/data tactile-zsl
# The first start trains the base model on the simulated dataset (a few minutes);
# set TACTILE_DATABASE_URL=postgresql://… to use PostgreSQL instead of /data.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

WORKDIR /app

# CPU-only torch from PyTorch's own index first: the default index would pull CUDA (GBs).
RUN pip install --index-url https://download.pytorch.org/whl/cpu "torch==2.13.0"

COPY pyproject.toml README.md ./
COPY app ./app
COPY worker ./worker
COPY migrations ./migrations
RUN pip install . && python -c "import app.api.main, worker, migrations"

RUN useradd --create-home --uid 10001 tactile && mkdir /data && chown tactile /data
USER tactile
# The tree grower, forest walk, nearest-trial pass and small-batch kernels are compiled by
# numba on first use and cached under the user's home (site-packages is read-only to this
# user); a small training run and one recognition fill that cache now, so the first start
# does not compile.
ENV NUMBA_CACHE_DIR=/home/tactile/.cache/numba
RUN tactile-zsl train --dataset simulated:6 --out /tmp/warm.bundle --quiet \
    && python -c "import numpy as np; np.save('/tmp/one.npy', np.zeros((1, 32, 30), np.float32))" \
    && tactile-zsl recognize --model /tmp/warm.bundle /tmp/one.npy > /dev/null \
    && rm /tmp/warm.bundle /tmp/one.npy
VOLUME ["/data"]

ENV TACTILE_DATA_DIR=/data \
    TACTILE_HOST=0.0.0.0 \
    TACTILE_PORT=8000
EXPOSE 8000

# /healthz answers once the model is loaded; the first start trains it, hence the long grace.
HEALTHCHECK --interval=30s --timeout=5s --start-period=15m --retries=3 \
    CMD python -c "import os, urllib.request; urllib.request.urlopen(f'http://127.0.0.1:{os.environ[\"TACTILE_PORT\"]}/healthz', timeout=4)"

CMD ["tactile-zsl", "serve"]
