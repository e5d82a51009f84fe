# A stand-in for redis:7 built from Debian's redis-server (7.0), for the tests on a machine that reaches no container
# registry. As in the official image: the server runs as "redis" in /data; the compose files give its command.
ARG DEBIAN=planner-test-debian:bookworm
FROM ${DEBIAN}
RUN apt-get update \
    && apt-get install --yes --no-install-recommends redis-server \
    && rm -rf /var/lib/apt/lists/* \
    && mkdir -p /data && chown redis:redis /data
WORKDIR /data
VOLUME /data
USER redis
EXPOSE 6379
CMD ["redis-server", "--protected-mode", "no"]
