# Component: localization (targets are added by the component's owner)
