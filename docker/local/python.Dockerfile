# A stand-in for python:3.11-slim built from Debian's packages, for the tests on a machine that reaches no container
# registry (tests/docker_images.py builds it FROM the debootstrapped bookworm it imports): Python 3.11 with its
# headers, in a venv whose python and pip come first on PATH, as the official image's do.
ARG DEBIAN=planner-test-debian:bookworm
FROM ${DEBIAN}
RUN apt-get update \
    && apt-get install --yes --no-install-recommends python3.11 python3.11-venv python3.11-dev \
    && rm -rf /var/lib/apt/lists/* \
    && python3.11 -m venv /opt/python \
    && /opt/python/bin/python -m pip install --no-cache-dir --quiet --upgrade pip
ENV PATH=/opt/python/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8
CMD ["python3"]
