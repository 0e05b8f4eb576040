"""launch_ros.substitutions.FindPackageShare: the package's share folder (the recorder's map)."""


class FindPackageShare:
    def __init__(self, package):
        self.package = package

    def perform(self, context) -> str:
        if self.package not in context.package_shares:
            raise LookupError(f"package {self.package!r} not found")
        return str(context.package_shares[self.package])
