# A stand-in for the official nginx image built from Debian's nginx (1.22), for the tests on a machine that reaches no
# container registry: the master runs as root with the configuration /etc/nginx/nginx.conf (compose.scale.yaml mounts
# docker/nginx.conf there, a whole configuration that reads the same in both images), logs on the container's output.
ARG DEBIAN=planner-test-debian:bookworm
FROM ${DEBIAN}
RUN apt-get update \
    && apt-get install --yes --no-install-recommends nginx \
    && rm -rf /var/lib/apt/lists/* /etc/nginx/sites-enabled/default \
    && ln -sf /dev/stdout /var/log/nginx/access.log && ln -sf /dev/stderr /var/log/nginx/error.log
EXPOSE 80
STOPSIGNAL SIGQUIT
CMD ["nginx", "-g", "daemon off;"]
